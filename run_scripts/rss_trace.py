#!/usr/bin/env python3
"""A process's resident memory over time: where a peak comes from (set-up, stepping, the final write).

    python3 run_scripts/rss_trace.py OUT.csv build/tissue run SCENE ...

Runs the command and polls its VmRSS every 20 ms into OUT.csv (seconds, kB); prints the peak (VmHWM at the end),
the largest VmRSS seen and the median of the last half of the samples before the peak's second half (the
stepping plateau when the run steps long enough). Exits with the command's exit code.
"""
import os
import subprocess
import sys
import time


def status(pid, key):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, command = sys.argv[1], sys.argv[2:]
    p = subprocess.Popen(command)
    t0, rows, hwm = time.monotonic(), [], 0
    while p.poll() is None:
        rows.append((time.monotonic() - t0, status(p.pid, "VmRSS:")))
        hwm = max(hwm, status(p.pid, "VmHWM:"))
        time.sleep(0.02)
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        f.write("seconds,rss_kB\n")
        for t, r in rows:
            f.write(f"{t:.3f},{r}\n")
    os.replace(tmp, out)
    seen = [r for _, r in rows if r > 0]
    if seen:
        top = max(seen)
        late = sorted(seen[len(seen) // 2:])
        print(f"rss_trace: peak (VmHWM) {hwm} kB, largest sample {top} kB, median of the second half {late[len(late) // 2]} kB, "
              f"{len(seen)} samples")
    sys.exit(p.returncode)


if __name__ == "__main__":
    main()
