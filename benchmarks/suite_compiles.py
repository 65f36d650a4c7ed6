"""Where the test suite's compile time goes: read the per-test logs that RBSIM_COMPILE_LOG=DIR makes the
suite write (tests/conftest.py) and print the tests and the files that compiled the most.

    RBSIM_COMPILE_LOG=/tmp/compiles NUMBA_CACHE_DIR=$(mktemp -d) python -m pytest -q
    python benchmarks/suite_compiles.py /tmp/compiles [--top 30]

With RBSIM_COMPILE_LOG_TYPES=run_chunk,find_contacts (names' parts) the log also carries those
functions' argument types; `--signatures` then lists each distinct signature of a function with its
compiles, and the function totals count them under the function's name.

CPU seconds of numba's outermost compiles (a compile inside another counts once), per test and summed
per test file; with an empty cache this is most of a cold suite's time.
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("directory", type=Path)
    parser.add_argument("--top", type=int, default=30)
    parser.add_argument("--signatures", metavar="NAME", help="the distinct argument types of this function's compiles")
    args = parser.parse_args()
    rows = [json.loads(line) for path in sorted(args.directory.glob("*.jsonl")) for line in path.open()]
    per_file: collections.Counter[str] = collections.Counter()
    for row in rows:
        per_file[row["test"].split("::", 1)[0]] += row["compile_cpu_s"]
    total = sum(row["compile_cpu_s"] for row in rows)
    print(f"compile CPU s in all: {total:.1f} over {len(rows)} tests that compiled")
    print("\nby file:")
    for name, seconds in per_file.most_common(args.top):
        print(f"  {seconds:7.1f}  {name}")
    own: collections.Counter[str] = collections.Counter()
    count: collections.Counter[str] = collections.Counter()
    for row in rows:
        for logged, seconds in row["functions"]:
            name = logged.split(" ", 1)[0]  # without the argument types RBSIM_COMPILE_LOG_TYPES adds
            own[name] += seconds
            count[name] += 1
    print("\nby function (its own compile time, callees left out; times compiled):")
    for name, seconds in own.most_common(args.top):
        print(f"  {seconds:7.1f}  {count[name]:3d}x  {name}")
    if args.signatures:
        signatures: dict[str, list[tuple[str, float]]] = collections.defaultdict(list)
        for row in rows:
            for logged, seconds in row["functions"]:
                name, _, types = logged.partition(" ")
                if name == args.signatures:
                    signatures[types or "(types not logged: RBSIM_COMPILE_LOG_TYPES)"].append((row["test"], seconds))
        print(f"\n{args.signatures}: {len(signatures)} distinct signatures")
        for types, compiles in sorted(signatures.items(), key=lambda item: -len(item[1])):
            print(f"  {len(compiles)}x, {sum(s for _, s in compiles):.1f} s, first in {compiles[0][0]}:\n    {types}")
    print("\nby test:")
    for row in sorted(rows, key=lambda r: -r["compile_cpu_s"])[: args.top]:
        top = sorted(((name.split(" ", 1)[0], s) for name, s in row["functions"]), key=lambda f: -f[1])[:4]
        print(f"  {row['compile_cpu_s']:7.1f}  {row['test']}  ({len(row['functions'])} functions; {top})")


if __name__ == "__main__":
    main()
