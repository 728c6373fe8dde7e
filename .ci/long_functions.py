#!/usr/bin/env python3
"""Lists the functions of the library and command-line code longer than a limit (lines from
the `fn` line to its closing brace), longest first. Tests, benches and examples are not counted.
Usage: long_functions.py [LIMIT=250] [--allow N]: with --allow, exit 1 when more than N
functions are longer than LIMIT (issue 36: at most one over 250 lines)."""
import pathlib, re, sys

args = sys.argv[1:]
ALLOW = None
if "--allow" in args:
    i = args.index("--allow")
    ALLOW = int(args[i + 1])
    del args[i : i + 2]
LIMIT = int(args[0]) if args else 250
ROOTS = [pathlib.Path("src")] + sorted(pathlib.Path("crates").glob("*/src"))
FN = re.compile(r"^\s*(pub(\([a-z]+\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?fn\s+([A-Za-z0-9_]+)")

def strip(line):
    # drop line comments and string contents, roughly (enough to count braces)
    line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
    line = re.sub(r"'(\\.|[^'\\])'", "''", line)
    return line.split("//")[0]

out = []
for root in ROOTS:
    for path in sorted(root.rglob("*.rs")):
        lines = path.read_text().splitlines()
        in_tests = False
        for i, line in enumerate(lines):
            if re.match(r"^\s*#\[cfg\(test\)\]", line):
                in_tests = True
            m = FN.match(line)
            if not m or in_tests:
                continue
            depth, started = 0, False
            for j in range(i, len(lines)):
                s = strip(lines[j])
                if not started and ";" in s and "{" not in s:
                    break
                depth += s.count("{") - s.count("}")
                if "{" in s:
                    started = True
                if started and depth <= 0:
                    n = j - i + 1
                    if n > LIMIT:
                        out.append((n, f"{path}:{i+1}", m.group(6)))
                    break
for n, where, name in sorted(out, reverse=True):
    print(f"{n:5} {name} {where}")
print(f"{len(out)} functions over {LIMIT} lines")
if ALLOW is not None and len(out) > ALLOW:
    print(f"error: at most {ALLOW} allowed; split the longest into named stages")
    sys.exit(1)
