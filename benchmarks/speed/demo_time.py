"""Cold and warm time of ``relnav demo``: wall clock and CPU time (user + sys of the demo and
its worker processes).

Cold: a fresh, empty numba cache (a temporary ``NUMBA_CACHE_DIR``), so every kernel the demo
runs is compiled, as on a first run after installing. Warm: the same command again with that
cache. The load average before and after is printed with the figures: on a shared machine the
wall time grows with the other jobs, the CPU time much less.

Usage::

    python benchmarks/speed/demo_time.py                # cold then warm, default demo
    python benchmarks/speed/demo_time.py --warm 3       # three warm runs after the cold one
    python benchmarks/speed/demo_time.py -- --jobs 1    # arguments after -- go to relnav demo
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed_demo(args: list[str], env: dict[str, str], out: Path) -> tuple[float, float, int]:
    """Run ``relnav demo --out OUT ARGS`` once; returns ``(wall_s, cpu_s, exit_code)``, the CPU
    time of the demo and every process it waited for (its workers)."""
    cmd = [sys.executable, "-m", "relnav.cli.main", "demo", "--out", str(out), *args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr.decode(errors="replace")[-2000:])
    return wall, cpu, proc.returncode


def main(argv: list[str] | None = None) -> int:
    """Measure and print the cold and warm demo times."""
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1 :]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--warm", type=int, default=1, help="warm runs after the cold one")
    ap.add_argument("--keep", type=Path, default=None, help="keep the last demo output here")
    ns = ap.parse_args(argv)

    tmp = Path(tempfile.mkdtemp(prefix="relnav-demo-time-"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba-cache"))
    rows = []
    try:
        print(f"cores usable: {len(os.sched_getaffinity(0))}; load average {os.getloadavg()}")
        for i in range(1 + ns.warm):
            kind = "cold" if i == 0 else "warm"
            wall, cpu, rc = timed_demo(extra, env, tmp / f"out{i}")
            rows.append((kind, wall, cpu, rc))
            print(f"{kind}: wall {wall:6.1f} s  cpu {cpu:6.1f} s  exit {rc}", flush=True)
            if rc != 0:
                return rc
        print(f"load average after: {os.getloadavg()}")
        if ns.keep is not None:
            shutil.copytree(tmp / f"out{ns.warm}", ns.keep, dirs_exist_ok=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
