"""Lines of src/ outside model/<family>/ that name a model family: what adding a family
costs outside its folder (issue 40's "a family plugs in at one place").

    python3 bench/family_lines.py [--family mask2former] [--pattern 'mask2former|m2f'] [-v]

Run from the repository root. Counts every line of src/**/*.rs outside
src/model/<family>/ that matches the pattern (case-insensitive), leaving out `//`
comment lines and everything from a file's first `#[cfg(test)]` on (tests sit at the
bottom of each file). Prints the total and the count per file; -v also prints the lines.
Standard library only.
"""

import argparse
import os
import re
import sys


def count(root, family, pattern):
    per_file = {}
    skip = os.path.join("src", "model", family) + os.sep
    for dirpath, _, files in os.walk(os.path.join(root, "src")):
        for name in sorted(files):
            if not name.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(dirpath, name), root)
            if rel.startswith(skip):
                continue
            hits = []
            with open(os.path.join(root, rel), encoding="utf-8") as f:
                for line in f:
                    s = line.strip()
                    if s.startswith("#[cfg(test)]"):
                        break
                    if s.startswith("//"):
                        continue
                    if re.search(pattern, line, re.IGNORECASE):
                        hits.append(s)
            if hits:
                per_file[rel] = hits
    return per_file


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--family", default="mask2former")
    ap.add_argument("--pattern", default="mask2former|m2f")
    ap.add_argument("-v", action="store_true")
    a = ap.parse_args()
    if not os.path.isdir("src"):
        sys.exit("run from the repository root (no src/ here)")
    per_file = count(".", a.family, a.pattern)
    total = sum(len(h) for h in per_file.values())
    print(f"{total} lines in {len(per_file)} files name {a.family} outside src/model/{a.family}/")
    for rel, hits in sorted(per_file.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        print(f"{len(hits):4} {rel}")
        if a.v:
            for h in hits:
                print(f"       {h}")


if __name__ == "__main__":
    main()
