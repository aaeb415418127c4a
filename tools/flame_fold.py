#!/usr/bin/env python3
"""Tidies folded stacks (inferno-collapse-perf output) of a `planet` profile for a flame graph.

Rayon's and Bevy's plumbing frames go, generic closure frames are named by the project function
they run in, and repeated frames fold into one, so that the graph shows the project's passes.
A parallel loop's work on a worker thread starts at the root (its caller's frames are on another
thread's stack). See docs/performance.md ("Flame graphs").

Usage: perf script -i perf.data | inferno-collapse-perf | python3 tools/flame_fold.py > out.folded
"""
import re
import sys

# Frames of the libraries' plumbing, by prefix.
NOISE = re.compile(
    r"^(rayon_core::|rayon::|bevy_ecs::|bevy_app::|core::|std::|__rust|alloc::|crossbeam"
    r"|catch_unwind|do_call|call_once|call_mut|halt_unwinding|in_worker|join_context|helper"
    r"|bridge|consume|drive|with_producer|callback|execute|run_inline|wait_until|main_loop"
    r"|start_thread|clone3|_start|__libc|planet$|\[unknown\]|_\[i\])"
)
# Frames dropped by their whole (generic) name.
DROP = {
    "run", "handle_unwind", "schedule_scope", "try_schedule_scope",
    "run_without_applying_deferred", "run_unsafe", "call_inner", "step", "collect",
    "par_extend", "from_par_iter", "extend", "from_iter", "map", "try_fold", "reduce", "sum",
    "fold", "for_each", "next", "main", "planet::main", "planet::cli::run",
}
# A project path inside a frame (a closure's frame names the function it belongs to).
OURS = re.compile(r"((?:systems|geometry|gpu|resources|io|simulation|plugins|random)::[A-Za-z0-9_:#]+)")


def clean(frame):
    """The frame's name as the graph shows it, or None to drop it."""
    f = frame.strip().replace("tectonic_planets::", "")
    found = OURS.findall(f)
    if found:
        return re.sub(r"::\{?closure(_env)?#\d+\}?.*$", "", found[-1]).rstrip(":")
    if NOISE.match(f) or f.startswith("{closure") or "rayon" in f or f.startswith("<"):
        return None
    for _ in range(6):
        f = re.sub(r"<[^<>]*>", "", f)
    f = f.replace("::{{closure}}", "").strip()
    if not f or f in DROP or f.startswith("::"):
        return None
    return f


def main():
    out = {}
    for line in sys.stdin:
        stack, _, count = line.rstrip().rpartition(" ")
        frames = [c for c in map(clean, stack.split(";")) if c and c not in DROP]
        folded = []
        for f in frames:
            if not folded or folded[-1] != f:
                folded.append(f)
        key = ";".join(["planet"] + folded)
        out[key] = out.get(key, 0) + int(count)
    for key, count in out.items():
        print(key, count)


if __name__ == "__main__":
    main()
