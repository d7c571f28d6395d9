#!/usr/bin/env python3
"""Checks the shape of the code (run by .ci/run). Fails, naming what is wrong, when:

1. two modules of one crate depend on each other. A module depends on another when its
   code (comments and tests left out) names `crate::other`. A module is a file
   (`src/name.rs`) or a folder (`src/name/`, with `mod.rs` or beside `src/name.rs`),
   whose files' code all counts as the module's;
2. a crate depends on one it must not (its `[dependencies]`; tests may use anything):
   the runtime (`format`, `player`, `bevy`) on no offline tool, and nothing on the
   encoder's side (`encoder`, `files`) on the baker: only the `vbim` command and the
   scene (which draws the baked terrain) may;
3. a file of `player/src/` is over 700 lines (a file that long mixes concerns);
4. a library crate whose public items must all be documented (format, files, player,
   encoder, bevy) lacks `#![deny(missing_docs)]`, which makes the compiler refuse any
   public item without a doc comment.
"""

import os
import re
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
CRATES = ["format/src", "files/src", "encoder/src", "bake/src", "player/src", "scene/src", "src"]
# Crate folder -> the workspace crates its [dependencies] must not name.
FORBIDDEN = {
    "format": {"vbim-encoder", "vbim-bake", "vbim-files", "vbim-player", "vbim-scene"},
    "player": {"vbim-encoder", "vbim-bake", "vbim-files", "vbim-scene"},
    "bevy": {"vbim-encoder", "vbim-bake", "vbim-files", "vbim-scene"},
    "files": {"vbim-encoder", "vbim-bake", "vbim-player", "vbim-scene"},
    "encoder": {"vbim-bake", "vbim-player", "vbim-scene"},
}
LONGEST = ("player/src", 700)
DOCUMENTED = ["format", "files", "player", "encoder", "bevy"]


def code_of(text):
    # The inline test module (always last) is left out; so is a `mod tests;` declaration,
    # whose file `modules` skips. Other test-only items early in a file (a helper under
    # `#[cfg(test)]`) must not hide the code after them, so the cut is at the module only.
    text = re.split(r"#\[cfg\(test\)\]\s*mod tests\s*\{", text)[0]
    text = re.sub(r"#\[cfg\(test\)\]\s*mod \w+\s*;", "", text)
    return "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))


def modules(crate):
    """Module name -> the source of its files (tests left out)."""
    mods = {}
    for f in sorted(os.listdir(crate)):
        full = os.path.join(crate, f)
        if f.endswith(".rs"):
            mods.setdefault(f[:-3], []).append(full)
        elif os.path.isdir(full):
            for dirpath, _, files in os.walk(full):
                mods.setdefault(f, []).extend(
                    os.path.join(dirpath, g) for g in files
                    if g.endswith(".rs") and g != "tests.rs")
    return {m: "\n".join(code_of(open(p, encoding="utf-8").read()) for p in ps)
            for m, ps in mods.items()}


def deps(crate):
    mods = modules(crate)
    names = set(mods)
    graph = {}
    for m, code in mods.items():
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


def dependencies(crate_dir):
    """The names in a Cargo.toml's [dependencies] table."""
    text = open(os.path.join(ROOT, crate_dir, "Cargo.toml"), encoding="utf-8").read()
    m = re.search(r"^\[dependencies\]\n(.*?)(?=^\[|\Z)", text, re.S | re.M)
    if not m:
        return set()
    return set(re.findall(r"^([A-Za-z0-9_\-]+)\s*=", m.group(1), re.M))


def main():
    bad = []
    for crate in CRATES:
        for c in cycles(deps(os.path.join(ROOT, crate))):
            bad.append(f"{crate}: module cycle {' -> '.join(c)}")
    for crate, forbidden in FORBIDDEN.items():
        for d in sorted(dependencies(crate) & forbidden):
            bad.append(f"{crate}/Cargo.toml: depends on {d}, which it must not")
    folder, most = LONGEST
    for dirpath, _, files in os.walk(os.path.join(ROOT, folder)):
        for f in files:
            if f.endswith(".rs"):
                p = os.path.join(dirpath, f)
                n = sum(1 for _ in open(p, encoding="utf-8"))
                if n > most:
                    bad.append(f"{os.path.relpath(p, ROOT)}: {n} lines, over {most}: split it by concern")
    for crate in DOCUMENTED:
        lib = open(os.path.join(ROOT, crate, "src", "lib.rs"), encoding="utf-8").read()
        if "#![deny(missing_docs)]" not in lib:
            bad.append(f"{crate}/src/lib.rs: lacks #![deny(missing_docs)]")
    for b in bad:
        print(b)
    print("check_cycles: ok" if not bad else f"check_cycles: {len(bad)} problem(s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
