#!/usr/bin/env python3
"""Mutation fuzzing of the lidar2d command line's inputs.

Runs the CLI on damaged copies of valid inputs and reports every run that crashes (a signal),
hangs (no exit within --timeout), trips a sanitizer, fails without a message, or fails and leaves
output files behind. A clean error (exit 1 or 2, one message) and a success both count as correct.
Use a sanitizer build (make test-asan builds build-asan/lidar2d) to catch memory errors that do not
crash. Deterministic per --seed. Each finding's input is kept under --work.

  tools/fuzz-cli.py BINARY [--modes carmen bag1 ros2 mcap table map png db options config state]
                    [--runs N] [--seed S] [-v]

Modes:
  carmen   CARMEN text logs: fields replaced by NaN/inf/garbage, lines cut, dropped, duplicated,
           binary lines, counts changed, gzip and cut gzip.
  bag1     ROS1 bags (the 1.2 and 2.0 bags of the shared data, and a bz2 one): bytes, lengths and floats changed;
           and the 2.0 demo bag with its chunk damaged inside and then compressed (bz2, or lz4 when
           python3-roslz4 is there: run with /usr/bin/python3), which a check outside the
           compression cannot see.
  ros2     a ROS2 bag: message blobs, topic rows and metadata.yaml damaged.
  mcap     MCAP files (tests/fixtures/mcap: chunked, unchunked, lz4, zstd, a split bag): bytes,
           and an uncompressed chunk's records (their bytes or lengths) damaged inside with the
           chunk's CRC made right again or 0, mostly with the data section's and summary's CRCs set
           to 0 ("not computed"), so the record and message parsers see the damage.
  table    range tables (poses.txt, angles.txt, ranges.txt made from a simulated log): tokens,
           lines cut, dropped, duplicated or binary, angles made uneven, gzip and cut gzip, a file
           missing.
  map      map YAML keys and PGM bytes (localize-index, map --prior, simulate --map).
  png      bare PNG maps (localize-index, localize, track, map --prior): the header's size, depth,
           colour type and interlacing changed, the pixel stream damaged and compressed again,
           chunks removed or repeated, all with valid CRCs; or plain bytes.
  db       localization database bytes (localize --db).
  options  every numeric option of every command at 0, -1, tiny, huge, NaN and inf.
  config   SLAM's --config YAML: each option alone at extreme values or of the wrong type, then
           several at once with lines cut, repeated or renamed.
  state    SLAM state files (state.l2d) through `slam --resume` and `track`: three small states made
           once (a 120-scan simulated log; that state resumed with a second log; the log with a
           kidnapping, for a lost track's fields), their payload decompressed, damaged and compressed
           again with the correct lengths and CRC-32 (what a buggy tool or a crafted file gives):
           any field by name set to an extreme (sizes and counts 0, off by one, 2^32, 2^63, 2^64-1;
           f64 NaN, inf, 1e308, -0; f32 ranges; flags 2, 255; kinds 3, 7, 255), whole elements of
           an array removed or repeated (a scan's beams all removed), random bytes, a cut, bytes
           appended or moved; and a few damaged headers (version, lengths, a wrong CRC, the
           writer string, a damaged zlib stream). An allocation over 2 GiB counts as a finding.
The shared data (../shared/data, or LIDAR2D_DATA_DIR) is needed by bag1 and ros2 (and png for the
rplidar room's map); a missing file skips its mode (or that input) with a message. -v prints every
run's exit code and last message line.
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
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get('LIDAR2D_DATA_DIR') or os.path.join(HERE, '..', '..', 'shared', 'data')


class Fuzzer:
    def __init__(self, binary, work, timeout, rng, verbose=False):
        self.bin, self.work, self.timeout, self.rng, self.verbose = binary, work, timeout, rng, verbose
        self.runs = self.findings = 0

    def run(self, args, keep, label, max_alloc_mb=None):
        """Runs the CLI (args may use {o}, a fresh output folder); keep() saves the input on a finding.
        With max_alloc_mb, a larger allocation is a sanitizer error (ASan's allocation-size-too-big)."""
        out = os.path.join(self.work, 'out')
        shutil.rmtree(out, ignore_errors=True)
        os.makedirs(out)
        args = [a.format(o=out) for a in args]
        asan = 'detect_leaks=0:abort_on_error=1' + (f':max_allocation_size_mb={max_alloc_mb}' if max_alloc_mb else '')
        env = dict(os.environ, ASAN_OPTIONS=asan, UBSAN_OPTIONS='halt_on_error=1')
        self.runs += 1
        try:
            p = subprocess.run([self.bin] + args, capture_output=True, timeout=self.timeout, env=env)
        except subprocess.TimeoutExpired:
            return self.report('HANG', label, args, '', keep)
        err = p.stderr.decode('utf-8', 'replace')
        left = os.listdir(out)
        if self.verbose:
            print(f'  exit {p.returncode}: {label}: {args[0]}: {(err.strip().splitlines() or [""])[-1][:160]}', flush=True)
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


def damageLine(rng, ls, i, op):
    """The damages every text mode shares, to line i of ls: 'c' cut, 'd' a line repeated here or
    this one dropped, 'b' a binary line inserted."""
    if op == 'c':
        ls[i] = ls[i][:rng.randrange(len(ls[i]) + 1)]
    elif op == 'd':
        ls.insert(i, ls[rng.randrange(len(ls))]) if rng.random() < 0.5 else ls.pop(i)
    elif op == 'b':
        ls.insert(i, ''.join(chr(rng.randrange(1, 256)) for _ in range(rng.randrange(1, 30))))


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
            elif op in 'cdb':
                damageLine(rng, ls, i, op)
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


# ---- SLAM state files (state.l2d; docs/file-formats.md, SLAM state) ----

class PayloadWalk:
    """Walks a state.l2d payload as decodeState reads it, recording each field (offset, struct
    format, name, role) and each array (name, offset of its count, each element's byte span), so that
    damage can hit a chosen field or remove and repeat whole elements."""

    def __init__(self, p):
        self.p, self.at, self.fields, self.arrays = p, 0, [], []

    def take(self, fmt, name, role):
        v = struct.unpack_from('<' + fmt, self.p, self.at)[0]
        self.fields.append((self.at, fmt, name, role))
        self.at += struct.calcsize(fmt)
        return v

    def size(self, name, role='size'):
        return self.take('Q', name, role)

    def real(self, name):
        return self.take('d', name, 'real')

    def flag(self, name):
        return self.take('B', name, 'flag')

    def string(self, name):
        n = self.size(name, 'count')
        self.at += n

    def pose(self, name):
        for _ in range(3):
            self.real(name)

    def opt(self, name, value):
        if self.flag(name):
            value()

    def array(self, name, item):
        at, spans = self.at, []
        for _ in range(self.size(name, 'count')):
            start = self.at
            item()
            spans.append((start, self.at))
        self.arrays.append((name, at, spans))


def walkState(p):
    w = PayloadWalk(p)

    def option():
        w.string('options.name')
        kind = w.take('B', 'options.type', 'kind')
        {0: lambda: w.flag('options.value'), 1: lambda: w.take('q', 'options.value', 'int'),
         2: lambda: w.size('options.value'), 3: lambda: w.real('options.value')}[kind]()

    def node():
        w.size('node.scan_index', 'index')
        w.real('node.time')
        w.pose('node.T_local_robot')
        w.pose('node.T_world_robot')
        w.size('node.submap', 'index')
        w.flag('node.degenerate')
        w.real('node.degenerate_dir_rad')
        for name in ('time', 'angle_min', 'angle_increment', 'range_min', 'range_max'):
            w.real('node.scan.' + name)
        w.array('node.scan.beams', lambda: w.take('f', 'node.scan.ranges', 'range'))
        w.pose('node.T_robot_laser')
        w.opt('node.T_odom_robot', lambda: w.pose('node.T_odom_robot'))
        w.size('node.frame_index')
        w.real('node.path_m')

    def scan():
        w.size('scan.frame_index')
        w.real('scan.time')
        w.size('scan.node', 'index')
        w.pose('scan.T_node_scan')
        for name in ('is_node', 'matched', 'degenerate'):
            w.flag('scan.' + name)
        w.real('scan.seconds')

    def submap():
        w.size('submap.anchor', 'index')
        w.array('submap.nodes', lambda: w.size('submap.node', 'index'))
        w.flag('submap.finished')
        w.opt('submap.last_link_node', lambda: w.size('submap.last_link_node', 'index'))
        w.pose('submap.last_link_T_anchor_node')

    def constraint():
        w.take('B', 'constraint.kind', 'kind')
        w.size('constraint.from', 'index')
        w.size('constraint.to', 'index')
        w.pose('constraint.T_from_to')
        for name in ('accepted', 'searched', 'descriptor'):
            w.flag('constraint.' + name)
        w.real('constraint.score')
        w.real('constraint.explained')
        w.string('constraint.reason')

    def edge():
        w.size('edge.from', 'index')
        w.size('edge.to', 'index')
        w.pose('edge.T_from_to')
        for _ in range(9):
            w.real('edge.sqrt_information')
        w.real('edge.huber_scale')
        w.flag('edge.scalable')

    def event():
        w.size('event.frame_index')
        w.real('event.time')
        w.string('event.what')

    w.array('options', option)
    w.array('sessions', lambda: (w.string('session.name'), w.size('session.first_scan', 'index')))
    w.array('nodes', node)
    w.array('scans', scan)
    w.array('submaps', submap)
    w.array('constraints', constraint)
    w.array('edges', edge)
    w.array('restarts', lambda: w.size('restart', 'index'))
    w.array('events', event)
    for _ in range(20):
        w.size('stats')
    for _ in range(3):
        w.real('stats')
    w.pose('T_world_local')
    w.opt('last_loop_node', lambda: w.size('last_loop_node', 'index'))
    w.opt('untied_since', lambda: w.size('untied_since', 'index'))
    w.opt('restart_odometry', lambda: [w.size('restart_odometry.' + x, 'index') for x in ('edge', 'constraint', 'node')])
    w.size('nodes_since_optimization')
    w.size('loops_since_optimization')
    assert w.at == len(p), 'the payload walk disagrees with the format'
    return w


def splitState(data):
    """(payload length, CRC-32, the decompressed payload) of a valid state.l2d."""
    at = 20 + struct.unpack_from('<Q', data, 12)[0]  # magic, version, writer string
    plen, crc, clen = struct.unpack_from('<QIQ', data, at)
    return zlib.decompress(data[at + 20:at + 20 + clen])


def packState(payload, version=1, writer=b'fuzz', plen=None, crc=None, clen=None, packed=None):
    """A state.l2d around `payload`: the lengths and CRC-32 correct unless given."""
    packed = zlib.compress(payload, 1) if packed is None else packed
    return (b'L2DSLAMS' + struct.pack('<IQ', version, len(writer)) + writer
            + struct.pack('<QIQ', len(payload) if plen is None else plen, zlib.crc32(packed) if crc is None else crc,
                          len(packed) if clen is None else clen) + packed)


HUGE_SIZES = [1 << 32, 1 << 63, (1 << 64) - 1, (1 << 33) + 1, 1 << 40]
STATE_REALS = [float('nan'), float('inf'), -float('inf'), 1e308, -1e308, -0.0, 0.0, 5e-324, 1e9, -1e9]
STATE_FLOATS = [float('nan'), float('inf'), -float('inf'), -1.0, 0.0, 3.4e38, 1e-45]


def damagePayload(rng, p, w):
    """One damage to the payload (walked by w): a field set to an extreme, an element removed or
    repeated, random bytes, a cut, bytes appended or moved. Returns (bytes, what was done)."""
    p = bytearray(p)
    op = rng.choice(['field'] * 6 + ['element'] * 2 + ['bytes', 'cut', 'append', 'shift'])
    if op == 'field':
        # A field by its name (each name as likely as any other, whether it occurs once or once per
        # beam), then one of its occurrences.
        name = rng.choice(sorted({x[2] for x in w.fields}))
        at, fmt, name, role = rng.choice([x for x in w.fields if x[2] == name])
        v = struct.unpack_from('<' + fmt, p, at)[0]
        if fmt == 'Q':
            new = rng.choice([0, 1, v - 1, v + 1, v + 2, 2 * v] + HUGE_SIZES + [rng.randrange(1 << 64)]) % (1 << 64)
        elif fmt == 'q':
            new = rng.choice([0, -1, 1 << 31, -(1 << 31) - 1, (1 << 63) - 1, -(1 << 63)])
        elif fmt == 'd':
            new = rng.choice(STATE_REALS + [-v, v * 1e6])
        elif fmt == 'f':
            new = rng.choice(STATE_FLOATS)
        elif role == 'kind':
            new = rng.choice([0, 1, 2, 3, 4, 7, 255])
        else:
            new = rng.choice([2, 255, v ^ 1])
        struct.pack_into('<' + fmt, p, at, new)
        return bytes(p), f'{name}={new}'
    if op == 'element':
        name = rng.choice(sorted({a[0] for a in w.arrays if a[2]}))
        name, at, spans = rng.choice([a for a in w.arrays if a[0] == name and a[2]])
        if name == 'node.scan.beams' and rng.random() < 0.3:  # a scan with no beams
            start, end = spans[0][0], spans[-1][1]
            struct.pack_into('<Q', p, at, 0)
            return bytes(p[:start] + p[end:]), f'{name}=0 (ranges removed)'
        start, end = rng.choice(spans)
        n = struct.unpack_from('<Q', p, at)[0]
        if rng.random() < 0.5:
            struct.pack_into('<Q', p, at, n - 1)
            return bytes(p[:start] + p[end:]), f'{name}: element at {start} removed'
        struct.pack_into('<Q', p, at, n + 1)
        return bytes(p[:end] + p[start:end] + p[end:]), f'{name}: element at {start} repeated'
    if op == 'bytes':
        for _ in range(rng.randrange(1, 6)):
            i = rng.randrange(len(p))
            p[i] = rng.randrange(256) if rng.random() < 0.5 else p[i] ^ (1 << rng.randrange(8))
        return bytes(p), 'bytes changed'
    if op == 'cut':
        i = rng.randrange(len(p))
        return bytes(p[:i]), f'cut at {i}'
    if op == 'append':
        extra = rng.choice([b'\x00', b'\x01', struct.pack('<Q', rng.choice(HUGE_SIZES)),
                            bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))])
        return bytes(p) + extra, f'{len(extra)} bytes appended'
    i, k = rng.randrange(len(p)), rng.randrange(1, 9)
    if rng.random() < 0.5:
        return bytes(p[:i] + p[i + k:]), f'{k} bytes removed at {i}'
    return bytes(p[:i] + bytes(k) + p[i:]), f'{k} bytes inserted at {i}'


def damageStateHeader(rng, payload):
    """A state.l2d whose header (not its payload) is wrong: version, lengths, CRC, writer string,
    a cut file, bytes after it, or a compressed stream that is not zlib (with its CRC)."""
    packed = zlib.compress(payload, 1)
    what = rng.choice(['version', 'plen', 'clen', 'crc', 'writer', 'cut', 'after', 'stream'])
    if what == 'version':
        v = rng.choice([0, 2, 0xFFFFFFFF])
        return packState(payload, version=v), f'version={v}'
    if what == 'plen':
        v = rng.choice([0, 1, len(payload) - 1, len(payload) + 1, 2 * len(payload), 1 << 32, (8 << 30),
                        (8 << 30) + 1, 1 << 63, (1 << 64) - 1])
        return packState(payload, plen=v), f'payload_length={v}'
    if what == 'clen':
        v = rng.choice([0, 1, len(packed) - 1, len(packed) + 1, 1 << 63, (1 << 64) - 1])
        return packState(payload, clen=v, packed=packed), f'compressed_length={v}'
    if what == 'crc':  # the payload damaged, its old CRC kept
        d = bytearray(packed)
        d[rng.randrange(len(d))] ^= 1 << rng.randrange(8)
        return packState(payload, crc=zlib.crc32(packed), packed=bytes(d)), 'checksum left wrong'
    if what == 'writer':
        d = bytearray(packState(payload))
        v = rng.choice([0, 1 << 20, 1 << 63, (1 << 64) - 1, len(d)])
        struct.pack_into('<Q', d, 12, v)
        return bytes(d), f'writer length={v}'
    if what == 'cut':
        d = packState(payload)
        i = rng.randrange(len(d))
        return d[:i], f'file cut at {i}'
    if what == 'after':
        return packState(payload) + b'\x00' * rng.randrange(1, 9), 'bytes after the payload'
    d = bytearray(packed)  # damaged inside the zlib stream, CRC recomputed
    for _ in range(rng.randrange(1, 4)):
        d[rng.randrange(len(d))] = rng.randrange(256)
    return packState(payload, packed=bytes(d)), 'zlib stream damaged (CRC recomputed)'


def fuzzState(f, base, runs):
    """Damaged SLAM states through `slam --resume` and `track`. The payload is damaged inside and
    compressed again with correct lengths and CRC-32 (what a buggy tool or a crafted file gives),
    so only the reader's checks of the contents stand between the damage and the pipeline."""
    d = os.path.join(base, 'state')
    os.makedirs(d, exist_ok=True)

    def j(*x):
        return os.path.join(d, *x)

    steps = [['simulate', '--world', 'office', '--scans', '120', '-o', j('sim.log')],
             ['simulate', '--world', 'office', '--scans', '30', '--seed', '7', '-o', j('sim2.log')],
             ['perturb', j('sim.log'), '--kidnap', '4@4', '--seed', '2', '-o', j('kidnap.log')],
             ['slam', j('sim.log'), '-o', j('one'), '-q'],
             ['slam', j('sim2.log'), '--resume', j('one', 'state.l2d'), '-o', j('two'), '-q'],
             ['slam', j('kidnap.log'), '-o', j('kidnap'), '-q']]
    for s in steps:
        subprocess.run([f.bin] + s, check=True, capture_output=True)
    # One session; two (the second resumed: sessions, restarts); a lost track across the kidnapping
    # (an untied fragment, the odometry across it).
    payloads = [splitState(open(j(x, 'state.l2d'), 'rb').read()) for x in ('one', 'two', 'kidnap')]
    walks = [walkState(p) for p in payloads]
    sim2, path = os.path.join(d, 'sim2.log'), os.path.join(f.work, 'state.l2d')
    rng = f.rng
    for n in range(runs):
        k = rng.randrange(len(payloads))
        if rng.random() < 0.15:
            data, what = damageStateHeader(rng, payloads[k])
        else:
            p, walk, done = payloads[k], walks[k], []
            for _ in range(rng.randrange(1, 4)):
                p, what = damagePayload(rng, p, walk)
                done.append(what)
                try:
                    walk = walkState(p)  # still well-formed: the next damage aims at its fields
                except (AssertionError, struct.error, KeyError, OverflowError, ValueError):
                    break
            data, what = packState(p), ', '.join(done)
        open(path, 'wb').write(data)
        for c in (['slam', sim2, '--resume', path, '-o', '{o}/s', '-q'], ['track', path, sim2, '-o', '{o}/t.txt', '-q']):
            f.run(c, f.keepFile(path), f'state #{n} ({what}) {c[0]}', max_alloc_mb=2048)


# ---- MCAP, range tables, bare PNG maps ----

MCAP_DIR = os.path.join(HERE, '..', 'tests', 'fixtures', 'mcap')
MCAP_MAGIC = b'\x89MCAP0\r\n'


def mcapRecords(d):
    """(opcode, content start, content length) of the records after the magic, up to DataEnd."""
    out, pos = [], len(MCAP_MAGIC)
    while pos + 9 <= len(d):
        op, n = d[pos], struct.unpack_from('<Q', d, pos + 1)[0]
        out.append((op, pos + 9, n))
        pos += 9 + n
        if op == 0x0F:
            break
    return out


def damagedChunk(rng, d):
    """An MCAP file whose uncompressed chunk is damaged inside (a record's bytes or its length, which
    the chunk's CRC would catch) with the CRC then made right again, or 0 ("not computed"), so that
    the reader's own checks of the records must hold. The chunk keeps its size: the summary's offsets
    stay valid."""
    d = bytearray(d)
    chunks = [r for r in mcapRecords(d) if r[0] == 0x06]
    _, at, n = rng.choice(chunks)
    comp_len = u32(d, at + 28)
    records_at = at + 32 + comp_len + 8
    size = struct.unpack_from('<Q', d, records_at - 8)[0]
    inner, q = [], records_at
    while q + 9 <= records_at + size:
        inner.append(q)
        q += 9 + struct.unpack_from('<Q', d, q + 1)[0]
    q = rng.choice(inner)
    length = struct.unpack_from('<Q', d, q + 1)[0]
    if rng.random() < 0.3:  # the record's length
        d[q + 1:q + 9] = struct.pack('<Q', rng.choice([0, 1, length - 1, length + 1, size, 1 << 32, (1 << 64) - 1]))
    else:  # its content, in place
        body = mutateBytes(rng, bytes(d[q + 9:q + 9 + length]), 3) if length else b''
        body = body[:length] + bytes(d[q + 9 + len(body):q + 9 + length])
        d[q + 9:q + 9 + length] = body
    plain = bytes(d[records_at:records_at + size])
    struct.pack_into('<I', d, at + 24, 0 if rng.random() < 0.3 else zlib.crc32(plain))
    return bytes(d)


def withoutDataCrc(original, damaged):
    """`damaged` with the DataEnd record's data_section_crc, where the original has it, and the
    Footer's summary_crc set to 0."""
    ends = [r for r in mcapRecords(original) if r[0] == 0x0F]
    if not ends or ends[0][1] + 4 > len(damaged):
        return damaged
    d = bytearray(damaged)
    d[ends[0][1]:ends[0][1] + 4] = b'\0\0\0\0'
    if len(d) == len(original) and original[-37] == 0x02:  # the Footer's summary_crc too
        d[-12:-8] = b'\0\0\0\0'
    return bytes(d)


def fuzzMcap(f, base, runs):
    files = sorted(x for x in os.listdir(MCAP_DIR) if x.endswith('.mcap')) if os.path.isdir(MCAP_DIR) else []
    if not files:
        print(f'mcap: skipped, no MCAP fixtures in {MCAP_DIR}')
        return
    commands = [['info', '{f}'], ['poses', '{f}', '-o', '{o}/p.txt'], ['map', '{f}', '-o', '{o}/m', '-q'],
                ['match', '{f}', '-o', '{o}/x.txt'], ['slam', '{f}', '-o', '{o}/s', '-q']]
    split = os.path.join(MCAP_DIR, 'split')
    rng = f.rng
    for n in range(runs):
        what = rng.choice(['bytes', 'bytes', 'chunk', 'chunk', 'split'])
        if what == 'split' and os.path.isdir(split):  # one file of a split bag, or its metadata
            path = os.path.join(f.work, 'in_split')
            shutil.rmtree(path, ignore_errors=True)
            shutil.copytree(split, path)
            name = rng.choice(sorted(os.listdir(path)))
            target = os.path.join(path, name)
            os.chmod(target, 0o644)
            data = open(target, 'rb').read()
            if name.endswith('.yaml'):
                m = data.decode().split('\n')
                i = rng.randrange(len(m))
                m[i] = m[i][:rng.randrange(len(m[i]) + 1)] + rng.choice(['', 'x', ': [', '-1', '999999999999', 'zstd'])
                data = '\n'.join(m).encode()
            else:
                data = mutateBytes(rng, data)
            open(target, 'wb').write(data)
            label = f'mcap #{n} (split, {name})'
        else:
            src = rng.choice(['chunked.mcap'] if what == 'chunk' else files)
            data = open(os.path.join(MCAP_DIR, src), 'rb').read()
            path = os.path.join(f.work, 'in.mcap')
            damaged = damagedChunk(rng, data) if what == 'chunk' else mutateBytes(rng, data)
            if rng.random() < 0.8:  # the data section's CRC (which would catch most damage) set to 0, "not computed"
                damaged = withoutDataCrc(data, damaged)
            open(path, 'wb').write(damaged)
            label = f'mcap #{n} ({src}, {what})'
        runLogCommands(f, path, label, commands)


def carmenScans(path):
    """(start angle, increment, count, ranges, truth pose) of each scan of lidar2d's own CARMEN log."""
    scans, truth = [], []
    for line in open(path):
        t = line.split()
        if t and t[0] == 'ROBOTLASER1':
            k = int(t[8])
            scans.append((float(t[2]), float(t[4]), [float(x) for x in t[9:9 + k]]))
        elif t and t[0] == 'TRUEPOS':
            truth.append(tuple(float(x) for x in t[1:4]))
    return scans, truth


def fuzzTable(f, base, runs):
    """Range tables (poses.txt, angles.txt, ranges.txt): tokens replaced, lines cut, dropped,
    duplicated or binary, the angles made uneven, files gzipped (and cut), one removed."""
    scans, truth = carmenScans(os.path.join(base, 'office.log'))
    start, inc, first = scans[0]
    files = {'angles.txt': [' '.join(repr(start + i * inc) for i in range(len(first)))],
             'ranges.txt': [', '.join(repr(r) for r in s[2]) for s in scans],
             'poses.txt': ['# x y theta'] + [' '.join(repr(v) for v in p) for p in truth]}
    rng = f.rng
    for n in range(runs):
        d = os.path.join(f.work, 'in_table')
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
        damaged, what = {k: list(v) for k, v in files.items()}, []
        for _ in range(rng.randrange(1, 4)):
            name = rng.choice(list(damaged))
            ls = damaged[name]
            if not ls:
                continue
            i = rng.randrange(len(ls))
            op = rng.choice('tttcdbue')
            what.append(f'{name}:{op}')
            toks = ls[i].replace(',', ' ').split()
            if op == 't' and toks:
                toks[rng.randrange(len(toks))] = rng.choice(TOKENS + ['1e6', '30', '0', '-0', ',', '#'])
                ls[i] = ' '.join(toks)
            elif op in 'cdb':
                damageLine(rng, ls, i, op)
            elif op == 'u' and len(toks) > 2:  # a value moved: uneven or decreasing angles
                j = rng.randrange(len(toks))
                try:
                    toks[j] = repr(float(toks[j]) + rng.choice([1e-3, -1e-3, 1.0, -10.0]))
                except ValueError:
                    pass
                ls[i] = ' '.join(toks)
            elif op == 'e':
                damaged[name] = ls[:i]
        for name, ls in damaged.items():
            data = ('\n'.join(ls) + '\n').encode('latin-1', 'replace')
            if rng.random() < 0.1:
                data = gzip.compress(data)
                if rng.random() < 0.4:
                    data = data[:rng.randrange(len(data))]
            if rng.random() < 0.03:
                what.append(f'{name} missing')
                continue
            open(os.path.join(d, name), 'wb').write(data)
        runLogCommands(f, d, f'table #{n} ({", ".join(what)})',
                       [['info', '{f}'], ['map', '{f}', '-o', '{o}/m', '-q'], ['slam', '{f}', '-o', '{o}/s', '-q'],
                        ['poses', '{f}', '-o', '{o}/p.txt']])


def pngChunks(d):
    out, pos = [], 8
    while pos + 12 <= len(d):
        n = struct.unpack_from('>I', d, pos)[0]
        out.append([bytes(d[pos + 4:pos + 8]), bytes(d[pos + 8:pos + 8 + n])])
        pos += 12 + n
    return out


def packPng(chunks):
    return b'\x89PNG\r\n\x1a\n' + b''.join(struct.pack('>I', len(data)) + kind + data
                                           + struct.pack('>I', zlib.crc32(kind + data)) for kind, data in chunks)


def damagedPng(rng, d):
    """A PNG damaged with its CRCs made right again: the header's size, depth, colour type or
    interlacing changed; the pixel stream decompressed, damaged (filter bytes, rows cut or added)
    and compressed again; chunks removed or repeated. Or plain bytes (caught by the CRCs)."""
    chunks = pngChunks(d)
    what = rng.choice(['header', 'header', 'pixels', 'pixels', 'chunks', 'bytes'])
    if what == 'bytes':
        return mutateBytes(rng, d), what
    if what == 'header':
        h = bytearray(chunks[0][1])
        field = rng.choice(['width', 'height', 'depth', 'colour', 'interlace', 'filter'])
        if field in ('width', 'height'):
            v = rng.choice([0, 1, 2, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 1 << 20, 100000])
            struct.pack_into('>I', h, 0 if field == 'width' else 4, v)
        else:
            h[{'depth': 8, 'colour': 9, 'filter': 11, 'interlace': 12}[field]] = rng.choice([0, 1, 2, 3, 4, 6, 16, 255])
        chunks[0][1] = bytes(h)
        return packPng(chunks), f'header {field}'
    idat = [c for c in chunks if c[0] == b'IDAT']
    if what == 'pixels' and idat:
        raw = bytearray(zlib.decompress(b''.join(c[1] for c in idat)))
        op = rng.choice(['filter', 'bytes', 'cut', 'more'])
        if op == 'filter':
            row = len(raw) // max(1, struct.unpack_from('>I', chunks[0][1], 4)[0])  # bytes per row
            raw[rng.randrange(0, len(raw), max(1, row))] = rng.choice([5, 6, 255])  # a row's filter byte
        elif op == 'bytes':
            raw = bytearray(mutateBytes(rng, bytes(raw)))
        elif op == 'cut':
            raw = raw[:rng.randrange(len(raw))]
        else:
            raw += bytes(rng.randrange(1, 5000))
        rest = [c for c in chunks if c[0] != b'IDAT']
        return packPng(rest[:-1] + [[b'IDAT', zlib.compress(bytes(raw))]] + rest[-1:]), f'pixels {op}'
    i = rng.randrange(len(chunks))
    chunks.insert(i, chunks[rng.randrange(len(chunks))]) if rng.random() < 0.5 else chunks.pop(i)
    return packPng(chunks), 'chunks'


def fuzzPng(f, base, runs):
    """Bare PNG maps (MAP.png --resolution R --origin X,Y,YAW) and map --prior masks."""
    sources = [os.path.join(base, 'map.png'), os.path.join(DATA, 'bags', 'rplidar-flipped', 'gridmap.png')]
    sources = [s for s in sources if os.path.exists(s)]
    query = os.path.join(base, 'query.log')
    rng = f.rng
    for n in range(runs):
        src = sources[n % len(sources)]
        data, what = damagedPng(rng, open(src, 'rb').read())
        path = os.path.join(f.work, 'in.png')
        open(path, 'wb').write(data)
        label = f'png #{n} ({os.path.basename(src)}, {what})'
        for c in (['localize-index', path, '--resolution', '0.05', '-o', '{o}/x.db', '--step', '1.0', '-q'],
                  ['localize', path, query, '--resolution', '0.05', '--origin', '-1,-1,0', '-o', '{o}/l.txt'],
                  ['track', path, query, '--resolution', '0.05', '-o', '{o}/t.txt', '-q'],
                  ['map', query, '-o', '{o}/m', '-q', '--prior', path, '--prior-resolution', '0.05']):
            f.run(c, f.keepFile(path), f'{label} {c[0]}', max_alloc_mb=2048)


CONFIG_VALUES = ['0', '-1', '1e-300', '1e308', 'nan', '.inf', '-.inf', '4294967296', '18446744073709551616',
                 '99999999', 'x', '[1, 2]', '{a: 1}', '', 'true', '1e9']


def fuzzConfig(f, base, runs):
    """SLAM's --config YAML: each option (from --dump-config) alone at extreme values and of the
    wrong type, then `runs` files with several options changed at once and lines damaged."""
    log = os.path.join(base, 'office.log')
    dump = subprocess.run([f.bin, 'slam', log, '--dump-config'], capture_output=True, check=True).stdout.decode()
    lines = dump.split('\n')
    keys = [i for i, l in enumerate(lines) if l and not l.startswith('#') and ':' in l]
    path = os.path.join(f.work, 'config.yaml')
    rng = f.rng

    def runWith(ls, label):
        open(path, 'w').write('\n'.join(ls))
        f.run(['slam', log, '--config', path, '-o', '{o}/s', '-q'], f.keepFile(path), label, max_alloc_mb=4096)

    for i in keys:
        name = lines[i].split(':')[0]
        for v in rng.sample(CONFIG_VALUES, 3):
            ls = list(lines)
            ls[i] = f'{name}: {v}'
            runWith(ls, f'config {name}: {v}')
    for n in range(runs):
        ls, what = list(lines), []
        for _ in range(rng.randrange(2, 6)):
            i = rng.choice(keys)
            name = ls[i].split(':')[0]
            op = rng.choice('vvvcdu')
            if op == 'v':
                ls[i] = f'{name}: {rng.choice(CONFIG_VALUES)}'
            elif op == 'c':
                ls[i] = ls[i][:rng.randrange(len(ls[i]) + 1)]
            elif op == 'd':
                ls.insert(i, ls[i])
            else:
                ls[i] = f'{name}_unknown: 1'
            what.append(f'{name} {op}')
        runWith(ls, f'config #{n} ({", ".join(what)})')


MODES = {'carmen': fuzzCarmen, 'bag1': fuzzBag1, 'ros2': fuzzRos2, 'map': fuzzMap, 'db': fuzzDb, 'options': fuzzOptions,
         'state': fuzzState, 'mcap': fuzzMcap, 'table': fuzzTable, 'png': fuzzPng,
         'config': fuzzConfig}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('binary', help='the lidar2d binary (a sanitizer build finds more)')
    ap.add_argument('--modes', nargs='+', default=list(MODES), choices=list(MODES))
    ap.add_argument('--runs', type=int, default=50, help='damaged inputs per mode (each runs several commands)')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--timeout', type=float, default=120, help='seconds before a run counts as a hang')
    ap.add_argument('--work', default='fuzz-work', help='folder for inputs and findings (emptied first)')
    ap.add_argument('-v', '--verbose', action='store_true', help='print every run\'s exit code and last message line')
    a = ap.parse_args()
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    f = Fuzzer(os.path.abspath(a.binary), os.path.abspath(a.work), a.timeout, random.Random(a.seed), a.verbose)
    base = prepare(f)
    for m in a.modes:
        before = (f.runs, f.findings)
        MODES[m](f, base, a.runs)
        print(f'{m}: {f.runs - before[0]} runs, {f.findings - before[1]} findings', flush=True)
    print(f'total: {f.runs} runs, {f.findings} findings')
    return 1 if f.findings else 0


if __name__ == '__main__':
    sys.exit(main())
