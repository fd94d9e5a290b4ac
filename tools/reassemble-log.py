#!/usr/bin/python3
"""Cut a CARMEN log written by `lidar2d perturb` (or any CARMEN log whose messages end with
`ipc_timestamp host logger_timestamp`) into thirds A, B, C by scan and write them in the order
B, A, C: the tracking benchmark's kidnapping (BENCHMARK.md, Tracking). Each scan keeps the lines
that follow its laser line; the times are rewritten to keep increasing (the original spacing
within each stretch, 1 s at each cut); poses and odometry are kept as logged, so the odometry
jumps at the cuts with the robot.

    tools/reassemble-log.py IN.log OUT.log
"""
import sys

LASERS = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip())
    header, scans = [], []
    with open(sys.argv[1]) as f:
        for line in f:
            fields = line.split()
            if fields and fields[0] in LASERS:
                scans.append([line])
            elif scans and fields and not line.startswith("#"):
                scans[-1].append(line)
            else:
                header.append(line)
    if len(scans) < 3:
        sys.exit(f"{sys.argv[1]}: {len(scans)} scans, at least 3 needed")
    n = len(scans)
    a, b = n // 3, 2 * n // 3
    stretches = [scans[a:b], scans[:a], scans[b:]]
    with open(sys.argv[2], "w") as out:
        out.writelines(header)
        t = None
        for stretch in stretches:
            first = float(stretch[0][0].split()[-3])
            t = 0.0 if t is None else t + 1.0
            shift = t - first
            for record in stretch:
                for line in record:
                    fields = line.split()
                    stamp = float(fields[-3]) + shift
                    fields[-3] = fields[-1] = f"{stamp:.6f}"
                    out.write(" ".join(fields) + "\n")
                t = float(record[0].split()[-3]) + shift


if __name__ == "__main__":
    main()
