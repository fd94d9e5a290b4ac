#!/usr/bin/env python3
"""Mutation fuzzing of the lidar2d command line's inputs.

Runs the CLI on damaged copies of valid inputs and reports every run that crashes (a signal),
hangs (no exit within --timeout), trips a sanitizer, fails without a message, or fails and leaves
output files behind. A clean error (exit 1 or 2, one message) and a success both count as correct.
Use a sanitizer build (make test-asan builds build-asan/lidar2d) to catch memory errors that do not
crash. Deterministic per --seed. Each finding's input is kept under --work.

  tools/fuzz-cli.py BINARY [--modes carmen bag1 ros2 map db options] [--runs N] [--seed S]

Modes:
  carmen   CARMEN text logs: fields replaced by NaN/inf/garbage, lines cut, dropped, duplicated,
           binary lines, counts changed, gzip and cut gzip.
  bag1     ROS1 bags (the 1.2 and 2.0 bags of the shared data, and a bz2 one): bytes, lengths and floats changed;
           and the 2.0 demo bag with its chunk damaged inside and then compressed (bz2, or lz4 when
           python3-roslz4 is there: run with /usr/bin/python3), which a check outside the
           compression cannot see.
  ros2     a ROS2 bag: message blobs, topic rows and metadata.yaml damaged.
  map      map YAML keys and PGM bytes (localize-index, map --prior, simulate --map).
  db       localization database bytes (localize --db).
  options  every numeric option of every command at 0, -1, tiny, huge, NaN and inf.
The shared data (../shared/data, or LIDAR2D_DATA_DIR) is needed by bag1 and ros2; a missing file
skips its mode with a message.
"""
import argparse
import gzip
import os
import random
import shutil
import sqlite3
import struct
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get('LIDAR2D_DATA_DIR') or os.path.join(HERE, '..', '..', 'shared', 'data')


class Fuzzer:
    def __init__(self, binary, work, timeout, rng):
        self.bin, self.work, self.timeout, self.rng = binary, work, timeout, rng
        self.runs = self.findings = 0

    def run(self, args, keep, label):
        """Runs the CLI (args may use {o}, a fresh output folder); keep() saves the input on a finding."""
        out = os.path.join(self.work, 'out')
        shutil.rmtree(out, ignore_errors=True)
        os.makedirs(out)
        args = [a.format(o=out) for a in args]
        env = dict(os.environ, ASAN_OPTIONS='detect_leaks=0:abort_on_error=1', UBSAN_OPTIONS='halt_on_error=1')
        self.runs += 1
        try:
            p = subprocess.run([self.bin] + args, capture_output=True, timeout=self.timeout, env=env)
        except subprocess.TimeoutExpired:
            return self.report('HANG', label, args, '', keep)
        err = p.stderr.decode('utf-8', 'replace')
        left = os.listdir(out)
        if p.returncode < 0 or p.returncode >= 128:
            return self.report(f'CRASH (exit {p.returncode})', label, args, err, keep)
        if 'runtime error:' in err or 'Sanitizer' in err:
            return self.report('SANITIZER', label, args, err, keep)
        if p.returncode != 0 and not err.strip():
            return self.report('SILENT FAILURE', label, args, err, keep)
        if p.returncode != 0 and left:
            return self.report(f'PARTIAL OUTPUT {left}', label, args, err, keep)

    def report(self, what, label, args, err, keep):
        self.findings += 1
        saved = keep(self.findings)
        print(f'{what}: {label}: lidar2d {" ".join(args)}\n  input kept: {saved}\n  '
              + err.strip()[-800:].replace('\n', '\n  '), flush=True)

    def keepFile(self, path):
        def keep(k):
            dst = os.path.join(self.work, f'finding-{k}-{os.path.basename(path)}')
            (shutil.copytree if os.path.isdir(path) else shutil.copy)(path, dst)
            return dst
        return keep


# ---- inputs made by the binary itself ----

def prepare(f):
    base = os.path.join(f.work, 'base')
    os.makedirs(base, exist_ok=True)
    log, query = os.path.join(base, 'office.log'), os.path.join(base, 'query.log')
    steps = [['simulate', '--world', 'office', '--scans', '40', '--rate', '2', '-o', log],
             ['simulate', '--world', 'office', '--scans', '4', '--seed', '5', '-o', query],
             ['map', log, '-o', os.path.join(base, 'map'), '-q'],
             ['localize-index', os.path.join(base, 'map.yaml'), '-o', os.path.join(base, 'map.db'), '--step', '1.0', '-q']]
    for s in steps:
        subprocess.run([f.bin] + s, check=True, capture_output=True)
    return base


# ---- modes ----

TOKENS = ['nan', 'NaN', 'inf', '-inf', '-1', '0', '1e308', '-1e308', '1e-320', 'x', '', '99999999999999999999',
          '4294967296', '0x10', '1.5.5', '1e', '100000000']
LOG_COMMANDS = [['info', '{f}'], ['map', '{f}', '-o', '{o}/m', '-q'], ['map', '{f}', '-o', '{o}/t', '-q', '--model', 'tsdf'],
                ['match', '{f}', '--method', 'p2l', '-o', '{o}/x.txt'], ['match', '{f}', '--method', 'corr', '-o', '{o}/x.txt'],
                ['degeneracy', '{f}', '-o', '{o}/d.txt'], ['poses', '{f}', '-o', '{o}/p.txt'], ['slam', '{f}', '-o', '{o}/s']]


def runLogCommands(f, path, label, commands=LOG_COMMANDS):
    for c in commands:
        f.run([a.replace('{f}', path) for a in c], f.keepFile(path), f'{label} {c[0]}')


def fuzzCarmen(f, base, runs):
    lines = open(os.path.join(base, 'office.log'), encoding='latin-1').read().split('\n')
    rng = f.rng
    for n in range(runs):
        ls = list(lines)
        for _ in range(rng.randrange(1, 4)):
            i = rng.randrange(len(ls))
            toks = ls[i].split(' ')
            op = rng.choice('ttttcddbnk')
            if op == 't':
                toks[rng.randrange(len(toks))] = rng.choice(TOKENS)
                ls[i] = ' '.join(toks)
            elif op == 'c':
                ls[i] = ls[i][:rng.randrange(len(ls[i]) + 1)]
            elif op == 'd':
                ls.insert(i, ls[rng.randrange(len(ls))]) if rng.random() < 0.5 else ls.pop(i)
            elif op == 'b':
                ls.insert(i, ''.join(chr(rng.randrange(1, 256)) for _ in range(rng.randrange(1, 30))))
            elif op == 'n' and len(toks) > 1:
                toks[1] = rng.choice(['0', '1', '2', '-5', '1000000000', '360'])
                ls[i] = ' '.join(toks)
            elif op == 'k':
                ls = ls[:i] or ['']
        data = '\n'.join(ls).encode('latin-1', 'replace')
        path = os.path.join(f.work, 'in.log')
        if rng.random() < 0.2:
            path += '.gz'
            data = gzip.compress(data)
            if rng.random() < 0.3:
                data = data[:rng.randrange(len(data))]
        for old in ('in.log', 'in.log.gz'):
            if os.path.exists(os.path.join(f.work, old)):
                os.remove(os.path.join(f.work, old))
        open(path, 'wb').write(data)
        runLogCommands(f, path, f'carmen #{n}')


def mutateBytes(rng, d, edits=5):
    d = bytearray(d)
    for _ in range(rng.randrange(1, edits + 1)):
        i = rng.randrange(len(d))
        op = rng.randrange(6)
        if op == 0:
            d[i] = rng.randrange(256)
        elif op == 1:
            d[i] ^= 1 << rng.randrange(8)
        elif op == 2 and i + 4 <= len(d):
            d[i:i + 4] = struct.pack('<I', rng.choice([0, 1, 0xFFFFFFFF, 0x7FFFFFFF, 1 << 20, len(d), rng.randrange(1 << 32)]))
        elif op == 3 and i + 4 <= len(d):
            d[i:i + 4] = struct.pack('<f', rng.choice([float('nan'), float('inf'), -1.0, 1e30, 0.0]))
        elif op == 4 and i + 8 <= len(d):
            d[i:i + 8] = struct.pack('<d', rng.choice([float('nan'), float('inf'), -1.0, 1e300]))
        elif op == 5 and rng.random() < 0.3:
            d = d[:i]
    return bytes(d)


def u32(d, at):
    return struct.unpack_from('<I', d, at)[0]


def recordFields(h):
    out, q = [], 0
    while q + 4 <= len(h):
        n = u32(h, q)
        name, _, value = bytes(h[q + 4:q + 4 + n]).partition(b'=')
        out.append([name, value])
        q += 4 + n
    return out


def packRecord(fields, data):
    h = b''.join(struct.pack('<I', len(k) + 1 + len(v)) + k + b'=' + v for k, v in fields)
    return struct.pack('<I', len(h)) + h + struct.pack('<I', len(data)) + data


def rechunked(rng, d):
    """A 2.0 bag whose chunks are decompressed, damaged inside (their records, which a check outside
    the compression cannot see), and compressed again with bz2 or (if python3-roslz4 is there) lz4;
    chunk_pos and index_pos follow the new chunk sizes. The stated size is the damaged data's,
    or sometimes the original's."""
    import bz2
    try:
        import roslz4
        kinds = ['bz2', 'lz4']
    except ImportError:
        roslz4, kinds = None, ['bz2']
    out, moved, pos, index_pos = bytearray(d[:13]), {}, 13, None
    head_at = None
    while pos + 8 <= len(d):
        hl = u32(d, pos)
        h, dl = d[pos + 4:pos + 4 + hl], u32(d, pos + 4 + hl)
        fields = recordFields(h)
        named = dict(fields)
        op = named.get(b'op', b'')
        if op == b'\x04':  # (laser_scan_matcher_demo.bag states other data lengths: trust the count)
            dl = 12 * struct.unpack('<I', named[b'count'])[0]
        data = d[pos + 8 + hl:pos + 8 + hl + dl]
        if op == b'\x03':
            head_at = len(out)
            out += d[pos:pos + 8 + hl + dl]
        elif op == b'\x05':
            comp = named.get(b'compression', b'none')
            plain = bz2.decompress(data) if comp == b'bz2' else roslz4.decompress(data) if comp == b'lz4' else data
            damaged = mutateBytes(rng, plain, 3)
            kind = rng.choice(kinds)
            packed = bz2.compress(damaged) if kind == 'bz2' else roslz4.compress(damaged)
            size = len(damaged) if rng.random() < 0.8 else len(plain)
            moved[pos] = len(out)
            out += packRecord([[b'op', b'\x05'], [b'compression', kind.encode()], [b'size', struct.pack('<I', size)]], packed)
        elif op in (b'\x06', b'\x07'):
            if index_pos is None:
                index_pos = len(out)
            for fld in fields:
                if fld[0] == b'chunk_pos' and struct.unpack('<Q', fld[1])[0] in moved:
                    fld[1] = struct.pack('<Q', moved[struct.unpack('<Q', fld[1])[0]])
            out += packRecord(fields, data)
        else:
            out += packRecord(fields, data)
        pos += 8 + hl + dl
    if head_at is not None and index_pos is not None:
        key = out.find(b'index_pos=', head_at)
        out[key + 10:key + 18] = struct.pack('<Q', index_pos)
    return bytes(out)


def fuzzBag1(f, base, runs):
    full = [['info', '{f}'], ['match', '{f}', '--init', 'identity', '-o', '{o}/x.txt'], ['slam', '{f}', '-o', '{o}/s']]
    # The two small bags (1.2, and 2.0 with a plain chunk) through every reading command; the
    # smallest bz2-compressed bag (2.0, 7 chunks, 1988 scans) through `info` only, to keep runs short.
    sources = [(os.path.join(DATA, 'bags', 'laser_scan_sparsifier_demo.bag'), full),
               (os.path.join(DATA, 'bags', 'laser_scan_matcher_demo.bag'), full),
               (os.path.join(DATA, 'raw', 'mit-csail.orig.bag'), [['info', '{f}']])]
    sources = [s for s in sources if os.path.exists(s[0])]
    if not sources:
        print(f'bag1: skipped, the shared data is missing ({DATA}/bags, {DATA}/raw)')
        return
    demo = os.path.join(DATA, 'bags', 'laser_scan_matcher_demo.bag')
    if os.path.exists(demo):  # its plain chunk damaged inside, then compressed
        sources.append((demo, full, 'rechunked'))
    for n in range(runs):
        src, commands, *how = sources[n % len(sources)]
        path = os.path.join(f.work, 'in.bag')
        data = open(src, 'rb').read()
        open(path, 'wb').write(rechunked(f.rng, data) if how else mutateBytes(f.rng, data))
        label = os.path.basename(src) + (', rechunked' if how else '')
        runLogCommands(f, path, f'bag1 #{n} ({label})', commands)


def fuzzRos2(f, base, runs):
    src = os.path.join(DATA, 'ros2', 'macfirst_floor_take_2')
    if not os.path.isdir(src):
        print(f'ros2: skipped, the shared data is missing ({src})')
        return
    rng = f.rng
    for n in range(runs):
        bag = os.path.join(f.work, 'in_ros2')
        shutil.rmtree(bag, ignore_errors=True)
        shutil.copytree(src, bag)
        for name in os.listdir(bag):
            os.chmod(os.path.join(bag, name), 0o644)
        os.chmod(bag, 0o755)
        what = rng.choice(['/scan', '/scan', '/odom', '/tf', '/tf_static', 'topics', 'metadata'])
        if what == 'metadata':
            m = open(os.path.join(bag, 'metadata.yaml')).read().split('\n')
            i = rng.randrange(len(m))
            m[i] = m[i][:rng.randrange(len(m[i]) + 1)] + rng.choice(['', 'x', ': [', '-1', '999999999999'])
            open(os.path.join(bag, 'metadata.yaml'), 'w').write('\n'.join(m))
        else:
            db = [os.path.join(bag, x) for x in os.listdir(bag) if x.endswith('.db3')][0]
            c = sqlite3.connect(db)
            if what == 'topics':
                col = rng.choice(['name', 'type', 'serialization_format'])
                c.execute(f'update topics set {col}=? where id=?',
                          (rng.choice(['', 'sensor_msgs/msg/LaserScan', 'x', '/scan']), rng.randrange(1, 7)))
            else:
                rows = c.execute('select m.id, m.data from messages m join topics t on m.topic_id=t.id where t.name=?',
                                 (what,)).fetchall()
                for _ in range(rng.randrange(1, 4)):
                    rid, data = rng.choice(rows)
                    c.execute('update messages set data=? where id=?', (mutateBytes(rng, data, 2), rid))
            c.commit()
            c.close()
        runLogCommands(f, bag, f'ros2 #{n} ({what})', [['info', '{f}'], ['map', '{f}', '-o', '{o}/m', '-q'],
                                                        ['match', '{f}', '-o', '{o}/x.txt']])


YAML_TOKENS = ['nan', '-1', '0', '1e308', '1e-300', 'inf', 'x', '', '[1, 2]', '[nan, 0, 0]', '2', '-0.5', '1.5',
               '99999999999', '"', '{', '/dev/zero', '/etc', 'missing.pgm']


def fuzzMap(f, base, runs):
    rng = f.rng
    yaml = open(os.path.join(base, 'map.yaml')).read()
    pgm = open(os.path.join(base, 'map.pgm'), 'rb').read()
    for n in range(runs):
        d = os.path.join(f.work, 'in_map')
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
        if rng.random() < 0.5:
            lines = yaml.split('\n')
            for _ in range(rng.randrange(1, 3)):
                i = rng.randrange(len(lines))
                if ':' in lines[i] and rng.random() < 0.8:
                    lines[i] = lines[i].split(':')[0] + ': ' + rng.choice(YAML_TOKENS)
                else:
                    lines[i] = lines[i][:rng.randrange(len(lines[i]) + 1)]
            open(os.path.join(d, 'map.yaml'), 'w').write('\n'.join(lines))
            open(os.path.join(d, 'map.pgm'), 'wb').write(pgm)
        else:
            open(os.path.join(d, 'map.yaml'), 'w').write(yaml)
            damaged = mutateBytes(rng, pgm[:64], 3) + pgm[64:] if rng.random() < 0.7 else mutateBytes(rng, pgm)
            open(os.path.join(d, 'map.pgm'), 'wb').write(damaged)
        y = os.path.join(d, 'map.yaml')
        for c in (['localize-index', y, '-o', '{o}/x.db', '--step', '1.0'],
                  ['map', os.path.join(base, 'query.log'), '-o', '{o}/m', '-q', '--prior', y],
                  ['simulate', '--map', y, '--scans', '3', '-o', '{o}/s.log']):
            f.run(c, f.keepFile(d), f'map #{n} {c[0]}')


def fuzzDb(f, base, runs):
    db = open(os.path.join(base, 'map.db'), 'rb').read()
    for n in range(runs):
        path = os.path.join(f.work, 'in.db')
        open(path, 'wb').write(mutateBytes(f.rng, db))
        f.run(['localize', os.path.join(base, 'map.yaml'), os.path.join(base, 'query.log'), '--db', path,
               '-o', '{o}/l.txt'], f.keepFile(path), f'db #{n}')


def fuzzOptions(f, base, runs):
    """Every numeric option of every command (from its --help) at extreme values; `runs` is unused."""
    log, yaml = os.path.join(base, 'query.log'), os.path.join(base, 'map.yaml')
    commands = {
        'simulate': ['simulate', '--world', 'office', '--scans', '3', '-o', '{o}/s.log'],
        'perturb': ['perturb', log, '-o', '{o}/p.log'],
        'eval': ['eval', log, '--truth', log],
        'map': ['map', log, '-o', '{o}/m', '-q'],
        'match': ['match', log, '-o', '{o}/x.txt'],
        'slam': ['slam', log, '-o', '{o}/s'],
        'degeneracy': ['degeneracy', log, '-o', '{o}/d.txt', '--snapshots', '{o}/snap'],
        'localize-index': ['localize-index', yaml, '-o', '{o}/x.db', '--step', '1.0'],
        'localize': ['localize', yaml, log, '-o', '{o}/l.txt', '--step', '1.0'],
    }
    values = ['0', '-1', '1e-12', '1e308', 'nan', 'inf', '-inf', '4294967296', '1e9', '1e-300']
    tuples = ['nan,0,0', '1e308,0,0', '0,0,1e308', '-1,-1,-1', '1,2', 'inf,inf,inf', '1e9,0,0']
    for name, base_args in commands.items():
        help_text = subprocess.run([f.bin, name, '--help'], capture_output=True, text=True).stdout
        for line in help_text.split('\n'):
            words = line.split()
            if len(words) < 2 or not words[0].startswith('-') or '--' not in words[0]:
                continue
            opt = words[0].split(',')[-1]
            kind = words[1]
            if opt in ('--output', '--help') or base_args.count(opt):
                continue
            if kind.startswith(('FLOAT', 'INT', 'UINT')):
                tried = values
            elif ',' in kind and kind.isupper():  # X,Y,THETA tuples
                tried = tuples
            else:
                continue
            for v in tried:
                f.run(base_args + [f'{opt}={v}'], lambda k: '(command line only)', f'options {name} {opt}={v}')


MODES = {'carmen': fuzzCarmen, 'bag1': fuzzBag1, 'ros2': fuzzRos2, 'map': fuzzMap, 'db': fuzzDb, 'options': fuzzOptions}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('binary', help='the lidar2d binary (a sanitizer build finds more)')
    ap.add_argument('--modes', nargs='+', default=list(MODES), choices=list(MODES))
    ap.add_argument('--runs', type=int, default=50, help='damaged inputs per mode (each runs several commands)')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--timeout', type=float, default=120, help='seconds before a run counts as a hang')
    ap.add_argument('--work', default='fuzz-work', help='folder for inputs and findings (emptied first)')
    a = ap.parse_args()
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    f = Fuzzer(os.path.abspath(a.binary), os.path.abspath(a.work), a.timeout, random.Random(a.seed))
    base = prepare(f)
    for m in a.modes:
        before = (f.runs, f.findings)
        MODES[m](f, base, a.runs)
        print(f'{m}: {f.runs - before[0]} runs, {f.findings - before[1]} findings', flush=True)
    print(f'total: {f.runs} runs, {f.findings} findings')
    return 1 if f.findings else 0


if __name__ == '__main__':
    sys.exit(main())
