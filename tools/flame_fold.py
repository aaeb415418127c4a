#!/usr/bin/env python3
"""Tidies folded stacks (inferno-collapse-perf output) of a `planet` profile for a flame graph.

Rayon's and Bevy's plumbing frames go, generic closure frames are named by the project function
they run in, and repeated frames fold into one, so that the graph shows the project's passes.
A parallel loop's work on a worker thread starts at the root (its caller's frames are on another
thread's stack). See docs/performance.md ("Flame graphs").

Usage: perf script -i perf.data | inferno-collapse-perf | python3 tools/flame_fold.py > out.folded
"""
import sys,re
noise=re.compile(r'^(rayon_core::|rayon::|bevy_ecs::|bevy_app::|core::|std::|__rust|alloc::|crossbeam|catch_unwind|do_call|call_once|call_mut|halt_unwinding|in_worker|join_context|helper|bridge|consume|drive|with_producer|callback|execute|run_inline|wait_until|main_loop|start_thread|clone3|_start|__libc|planet$|\[unknown\]|_\[i\])')
drop={'run','handle_unwind','schedule_scope','try_schedule_scope','run_without_applying_deferred','run_unsafe','call_inner','step','collect','par_extend','from_par_iter','extend','from_iter','map','try_fold','reduce','sum','fold','for_each','next','main','planet::main','planet::cli::run'}
ours=re.compile(r'((?:systems|geometry|gpu|resources|io|simulation|plugins|random)::[A-Za-z0-9_:#]+)')
def clean(f):
    f=f.strip().replace('tectonic_planets::','')
    m=ours.findall(f)
    if m:
        name=m[-1]
        name=re.sub(r'::\{?closure(_env)?#\d+\}?.*$','',name).rstrip(':')
        return name
    if noise.match(f) or f.startswith('{closure') or 'rayon' in f or f.startswith('<'): return None
    g=f
    for _ in range(6): g=re.sub(r'<[^<>]*>','',g)
    g=g.replace('::{{closure}}','').strip()
    if not g or g in drop or g.startswith('::'): return None
    return g
out={}
for l in sys.stdin:
    stack,_,v=l.rstrip().rpartition(' ')
    fr=[clean(f) for f in stack.split(';')]
    fr=[f for f in fr if f and f not in drop]
    ded=[]
    for f in fr:
        if not ded or ded[-1]!=f: ded.append(f)
    k=';'.join(['planet']+ded)
    out[k]=out.get(k,0)+int(v)
for k,v in out.items(): print(k,v)
