#!/usr/bin/env python3
"""Checks that the repository stands alone (run by .ci/run).

1. No tracked file refers to a path outside the repository: not the team's shared folder
   beside the checkout, and no relative path that climbs above the repository root from the file that names it.
2. Every relative link in a Markdown file points at a file that exists.
3. Every repository path that docs/ARCHITECTURE.md names (in backticks) exists, and every
   source file (`*/src/**.rs`, `*.wgsl`) is named there: the tour stays complete.
4. No document or comment is a work log: nothing names the working session that wrote it
   ("session" and a number). Docs give current figures and reasons; history is git's.

Exits 1 naming each offending file and line.
"""

import os
import re
import subprocess
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
TEXT = (".rs", ".md", ".toml", ".sh", ".py", ".wgsl", ".json", ".txt", ".yml", ".yaml")
SHARED = "../" + "shared"
CLIMB = re.compile(r"(?:\.\./)+[A-Za-z0-9_.\-/]*")
LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")
TICKED = re.compile(r"`([A-Za-z0-9_.\-/]+)`")
# "session 20", "sessions 6–7", "Session 14's": a dated work log.
WORKLOG = re.compile(r"\bsessions?[\s-]+\d+", re.IGNORECASE)
TOP = ("bake/", "bevy/", "encoder/", "files/", "format/", "player/", "scene/", "src/", "samples/", "docs/",
       "scripts/", "tests/", "assets/", ".ci/")


def tracked():
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    return [f for f in out.splitlines() if f.endswith(TEXT) and f != "Cargo.lock"]


def inside(path):
    return os.path.commonpath([ROOT, os.path.abspath(path)]) == ROOT


def main():
    bad = []
    for f in tracked():
        full = os.path.join(ROOT, f)
        try:
            lines = open(full, encoding="utf-8").read().splitlines()
        except (UnicodeDecodeError, FileNotFoundError):
            continue
        here = os.path.dirname(full)
        for n, line in enumerate(lines, 1):
            if SHARED in line or ("PROTOCOL" + ".md") in line:
                bad.append(f"{f}:{n}: refers to a file outside the repository "
                           "(the conventions are docs/CONVENTIONS.md)")
            for m in CLIMB.finditer(line):
                if not inside(os.path.join(here, m.group(0))):
                    bad.append(f"{f}:{n}: {m.group(0)} climbs out of the repository")
            if WORKLOG.search(line) and f != "scripts/check_docs.py":
                bad.append(f"{f}:{n}: names a working session ({WORKLOG.search(line).group(0)!r}): "
                           "say what is true now and why, not when it was done")
            if f.endswith(".md"):
                for m in LINK.finditer(line):
                    target = m.group(1)
                    if re.match(r"[a-z]+:", target):
                        continue
                    p = os.path.join(here, target)
                    if not inside(p):
                        bad.append(f"{f}:{n}: link {target} leaves the repository")
                    elif not os.path.exists(p):
                        bad.append(f"{f}:{n}: link {target} does not exist")
    arch = os.path.join(ROOT, "docs", "ARCHITECTURE.md")
    for n, line in enumerate(open(arch, encoding="utf-8").read().splitlines(), 1):
        for m in TICKED.finditer(line):
            p = m.group(1)
            if p.startswith(TOP) and not os.path.exists(os.path.join(ROOT, p)):
                bad.append(f"docs/ARCHITECTURE.md:{n}: names {p}, which does not exist")
    tour = open(arch, encoding="utf-8").read()
    for f in tracked():
        if re.fullmatch(r"([a-z]+/)?src/([a-z_0-9]+/)*[a-z_0-9]+\.(rs|wgsl)", f) and f not in tour:
            bad.append(f"docs/ARCHITECTURE.md does not name {f}")
    for b in bad:
        print(b)
    if bad:
        print(f"check_docs: {len(bad)} problem(s)")
        return 1
    print("check_docs: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
