"""Where a cold ``relnav demo`` spends its numba compilation: every compiled signature with its
own (exclusive) compile time, and the top-level compiles with everything they pulled in.

Run it with an empty cache so that everything compiles, in one process (``--jobs 1``)::

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/speed/demo_compile_profile.py -- --jobs 1

Arguments after ``--`` go to ``relnav demo`` (default output folder: a temporary one). A
function compiled more than once (several signatures, e.g. a literal argument) is listed with
its signatures: fewer specialisations, fewer compiles.
"""

from __future__ import annotations

import collections
import sys
import tempfile
import time


def main(argv: list[str] | None = None) -> int:
    """Run the demo under numba's compile events and print the compile times."""
    from numba.core import event

    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    own: dict[str, list] = collections.defaultdict(lambda: [0, 0.0, []])
    top: dict[str, float] = collections.defaultdict(float)

    class Listener(event.Listener):
        def __init__(self) -> None:
            self.stack: list[list[float]] = []

        def on_start(self, ev: event.Event) -> None:
            self.stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev: event.Event) -> None:
            d = ev.data["dispatcher"]
            t0, children = self.stack.pop()
            dt = time.perf_counter() - t0
            name = f"{d.py_func.__module__}.{d.py_func.__qualname__}"
            rec = own[name]
            rec[0] += 1
            rec[1] += dt - children
            rec[2].append(str(ev.data["args"]))
            if self.stack:
                self.stack[-1][1] += dt
            else:
                top[name] += dt

    event.register("numba:compile", Listener())
    from relnav.cli.main import app

    if "--out" not in extra and "-o" not in extra:
        extra += ["--out", tempfile.mkdtemp(prefix="relnav-demo-")]
    t0 = time.perf_counter()
    try:
        app(["demo", *extra], standalone_mode=False)
    except SystemExit:
        pass
    total = time.perf_counter() - t0
    print(f"demo {total:.1f} s (this process), numba compilation {sum(top.values()):.1f} s")
    n_rel = sum(v[0] for k, v in own.items() if k.startswith("relnav"))
    print(f"compiled signatures: {n_rel} of relnav's, {sum(v[0] for v in own.values())} in all")
    print("top-level compiles (inclusive):")
    for name, dt in sorted(top.items(), key=lambda kv: -kv[1]):
        print(f"  {dt:6.2f} s  {name}")
    print("every compiled function (exclusive, 30 largest):")
    for name, (n, dt, sigs) in sorted(own.items(), key=lambda kv: -kv[1][1])[:30]:
        print(f"  {dt:6.2f} s  {n:2d}x  {name}")
        if n > 1 and name.startswith("relnav"):
            for s in sigs:
                print(f"             {s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
