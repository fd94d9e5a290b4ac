#!/usr/bin/env python3
"""Checks that every #include of the library respects the module layering.

The rule comes from the build: CMakeLists.txt declares each module with the modules it may use
(`lidar2d_module(NAME DEPS ...)`) and writes them to lidar2d_layers.json in the build folder. This
script reads that file and every source and header of the library and the CLI:

- a file of module M (include/lidar2d/M/ or src/M/) may include `lidar2d/X/...` and `src/X/...`
  only when X is M or one of M's DEPS;
- `src/X/internal/...` is private to module X;
- public headers (include/) never include `src/...` (they are installed; src/ is not);
- library files use only project-rooted includes (`lidar2d/...`, `src/...`), no relative ones;
- the CLI (apps/) uses public headers only;
- every folder under src/ and include/lidar2d/ is a declared module, and DEPS form no cycle.

Exit 0 when all hold; otherwise one line per violation (file:line: what) and exit 1.
Usage: check-layers.py LAYERS_JSON [--root DIR]
"""
import argparse
import json
import pathlib
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')


def find_cycle(deps):
    state = {}

    def visit(m, stack):
        state[m] = 1
        for d in deps.get(m, []):
            if state.get(d) == 1:
                return stack + [m, d]
            if state.get(d) is None:
                found = visit(d, stack + [m])
                if found:
                    return found
        state[m] = 2
        return None

    for m in deps:
        if state.get(m) is None:
            found = visit(m, [])
            if found:
                return found
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("layers_json")
    ap.add_argument("--root", default=str(pathlib.Path(__file__).resolve().parent.parent))
    args = ap.parse_args()
    root = pathlib.Path(args.root)
    deps = json.loads(pathlib.Path(args.layers_json).read_text())
    errors = []

    for m, ds in deps.items():
        for d in ds:
            if d not in deps:
                errors.append(f"{args.layers_json}: module {m} depends on undeclared module {d}")
    cycle = find_cycle(deps)
    if cycle:
        errors.append(f"{args.layers_json}: dependency cycle: {' -> '.join(cycle)}")

    for base in (root / "src", root / "include" / "lidar2d"):
        if base.is_dir():
            for d in sorted(p for p in base.iterdir() if p.is_dir()):
                if d.name not in deps:
                    errors.append(f"{d.relative_to(root)}: folder is not a module declared in CMakeLists.txt")

    def check_file(path, module, public):
        rel = path.relative_to(root)
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            m = INCLUDE.match(line)
            if not m:
                continue
            inc = m.group(1)
            parts = inc.split("/")
            if module is None:  # the CLI
                if parts[0] == "src":
                    errors.append(f"{rel}:{n}: the CLI includes library-private {inc}")
                continue
            allowed = {module, *deps.get(module, [])}
            if parts[0] == "lidar2d" and len(parts) > 2:
                target = parts[1]
            elif parts[0] == "src" and len(parts) > 2:
                target = parts[1]
                if public:
                    errors.append(f"{rel}:{n}: public header includes library-private {inc}")
                if len(parts) > 3 and parts[2] == "internal" and target != module:
                    errors.append(f"{rel}:{n}: {inc} is internal to module {target}")
            else:
                errors.append(f"{rel}:{n}: include \"{inc}\" is not project-rooted (lidar2d/... or src/...)")
                continue
            if target not in allowed:
                errors.append(f"{rel}:{n}: module {module} may not use module {target} ({inc}); "
                              f"it may use: {', '.join(sorted(deps.get(module, []))) or 'nothing'}")

    for module in deps:
        for base, public in ((root / "include" / "lidar2d" / module, True), (root / "src" / module, False)):
            if base.is_dir():
                for path in sorted(base.rglob("*")):
                    if path.suffix in (".hpp", ".cpp", ".h"):
                        check_file(path, module, public)
    apps = root / "apps"
    if apps.is_dir():
        for path in sorted(apps.rglob("*")):
            if path.suffix in (".hpp", ".cpp"):
                check_file(path, None, False)

    for e in errors:
        print(e)
    if errors:
        print(f"check-layers: {len(errors)} violation(s)")
        return 1
    print(f"check-layers: {len(deps)} modules, every include respects the layering")
    return 0


if __name__ == "__main__":
    sys.exit(main())
