#!/usr/bin/env python3
"""Fails when two modules of one crate depend on each other (run by .ci/run).

A module depends on another when its code (comments and tests left out) names
`crate::other`. Every crate keeps its modules flat (one file each), so this sees them all.
"""

import os
import re
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
CRATES = ["format/src", "encoder/src", "bake/src", "player/src", "scene/src", "src"]


def code_of(text):
    text = text.split("#[cfg(test)]")[0]
    return "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))


def deps(crate):
    names = {f[:-3] for f in os.listdir(crate) if f.endswith(".rs")}
    graph = {}
    for m in names:
        code = code_of(open(os.path.join(crate, m + ".rs"), encoding="utf-8").read())
        used = set(re.findall(r"crate::([a-z_0-9]+)", code))
        for group in re.findall(r"use crate::\{([^}]*)\}", code):
            used |= {p.strip().split("::")[0] for p in group.split(",") if p.strip()}
        graph[m] = (used & names) - {m}
    return graph


def cycles(graph):
    state, stack, found = {}, [], []

    def visit(u):
        state[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                found.append(stack[stack.index(v):] + [v])
            elif v not in state:
                visit(v)
        stack.pop()
        state[u] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    return found


def main():
    bad = 0
    for crate in CRATES:
        for c in cycles(deps(os.path.join(ROOT, crate))):
            print(f"{crate}: module cycle {' -> '.join(c)}")
            bad += 1
    print("check_cycles: ok" if not bad else f"check_cycles: {bad} cycle(s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
