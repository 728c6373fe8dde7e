#!/usr/bin/env python3
"""Import circles between the modules of the workspace's crates (a file is a module).

A module's imports are the `crate::...` and `super::...` paths it names outside its tests;
a path is resolved to the deepest module it names (an old path that a crate re-exports from
its root, `pub use room::{a, b}`, resolves to the module it names now). A module naming its
own ancestor (a child calling its parent's helpers) is the usual parent/child pattern and is
not counted. Prints each strongly connected group of modules and exits 1 when there is one.

    python3 .ci/import_cycles.py crates/*/src src     # check these crates' sources
    python3 .ci/import_cycles.py --self-test           # the check finds a planted circle
"""
import os
import re
import sys
import tempfile


def modules(root):
    mods = {}
    for dp, _, fs in os.walk(root):
        for f in fs:
            if not f.endswith(".rs"):
                continue
            p = os.path.join(dp, f)
            rel = os.path.relpath(p, root)[:-3].split(os.sep)
            if rel[0] == "bin":
                continue
            if rel[-1] in ("mod", "lib", "main"):
                rel = rel[:-1]
            mods[tuple(rel)] = p
    return mods


def aliases(root, mods):
    out = {}
    lib = os.path.join(root, "lib.rs")
    text = open(lib).read() if os.path.exists(lib) else ""
    for m in re.finditer(r"pub use (\w+)::\{([^}]*)\};", text):
        for n in m.group(2).split(","):
            n = n.strip()
            if n and (m.group(1), n) in mods:
                out[(n,)] = (m.group(1), n)
    for m in re.finditer(r"pub use (\w+)::(\w+);", text):
        if (m.group(1), m.group(2)) in mods:
            out[(m.group(2),)] = (m.group(1), m.group(2))
    return out


def edges(root):
    mods = modules(root)
    alias = aliases(root, mods)

    def resolve(path):
        path = tuple(path)
        if path[:1] in alias:
            path = alias[path[:1]] + path[1:]
        for k in range(len(path), 0, -1):
            if path[:k] in mods:
                return path[:k]
        return None

    out = {m: set() for m in mods}
    for m, p in mods.items():
        s = open(p).read()
        s = re.sub(r"#\[cfg\(test\)\]\s*mod tests\s*\{.*", "", s, flags=re.S)
        s = re.sub(r"//.*", "", s)

        def add(parts):
            t = resolve(parts)
            if t and t != m and m[: len(t)] != t:
                out[m].add(t)

        for g in re.finditer(r"(crate|super)((?:::\w+)*)::\{([^;]*?)\};", s, flags=re.S):
            base = g.group(2).strip(":").split("::") if g.group(2) else []
            if g.group(1) == "super":
                base = list(m[:-1]) + base
            for item in re.sub(r"\{[^}]*\}", "", g.group(3)).split(","):
                item = item.strip().split(" as ")[0]
                if item:
                    add(base + item.split("::"))
        for g in re.finditer(r"\b(crate|super)((?:::\w+)+)", s):
            parts = g.group(2).strip(":").split("::")
            if g.group(1) == "super":
                parts = list(m[:-1]) + parts
            add(parts)
    return out


def cycles(graph):
    """Strongly connected groups of more than one module (Tarjan)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted("::".join(x) or "lib" for x in group))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def self_test():
    with tempfile.TemporaryDirectory() as d:
        os.makedirs(os.path.join(d, "room"))
        files = {
            "lib.rs": "pub mod room;\npub mod b;\npub use room::a;\n",
            "room/mod.rs": "pub mod a;\n",
            "room/a.rs": "use crate::b::B;\n",
            "b.rs": "pub struct B;\nfn f() { crate::a::g() }\n",
        }
        for name, text in files.items():
            with open(os.path.join(d, name), "w") as f:
                f.write(text)
        assert cycles(edges(d)) == [["b", "room::a"]], cycles(edges(d))
        with open(os.path.join(d, "b.rs"), "w") as f:
            f.write("pub struct B;\n")
        assert cycles(edges(d)) == []
    print("import_cycles self-test: a planted circle is found, and gone when broken")


def main(args):
    if args == ["--self-test"]:
        self_test()
        return 0
    bad = 0
    for root in args:
        found = cycles(edges(root))
        print(f"{root}: {len(found)} import circle(s)")
        for group in found:
            print("   ", " <-> ".join(group))
        bad += len(found)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
