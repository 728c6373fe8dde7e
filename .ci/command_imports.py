#!/usr/bin/env python3
"""No command of the `cpm` command line imports another command's module (issue 36): what two
commands share lives in the workflow crate (crates/cpm-workflow) or in `src/cli/common.rs`
(shared arguments). A command is a module of src/cli named in its `Command` enum: `X.rs` or the
folder `X/`. Exit 1 naming each offending line."""
import pathlib
import re
import sys

CLI = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "src/cli")
COMMANDS = sorted(
    p.stem if p.is_file() else p.name
    for p in CLI.iterdir()
    if (p.suffix == ".rs" and p.stem not in ("mod", "common", "formulation")) or p.is_dir()
)


def files_of(command):
    f = CLI / f"{command}.rs"
    return [f] if f.exists() else sorted((CLI / command).rglob("*.rs"))


def offences(command, path):
    others = [c for c in COMMANDS if c != command]
    pat = re.compile(
        r"\b(?:super|crate::cli|cpm::cli|super::super)::(" + "|".join(others) + r")\b"
    )
    for n, line in enumerate(path.read_text().splitlines(), 1):
        code = line.split("//")[0]
        m = pat.search(code)
        if m:
            yield f"{path}:{n}: the command `{command}` imports the command `{m.group(1)}`: {line.strip()}"


def self_test():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        cli = pathlib.Path(d)
        (cli / "mod.rs").write_text("pub mod a;\npub mod b;\n")
        (cli / "a.rs").write_text("use super::b::Thing;\n")
        (cli / "b.rs").write_text("// super::a::x in a comment is fine\nuse super::common;\n")
        global CLI, COMMANDS
        saved = CLI, COMMANDS
        CLI, COMMANDS = cli, ["a", "b"]
        found = [o for c in COMMANDS for f in files_of(c) for o in offences(c, f)]
        CLI, COMMANDS = saved
        assert len(found) == 1 and "`a` imports the command `b`" in found[0], found


if __name__ == "__main__":
    self_test()
    found = [o for c in COMMANDS for f in files_of(c) for o in offences(c, f)]
    for o in found:
        print(o)
    print(f"{len(COMMANDS)} commands ({', '.join(COMMANDS)}), {len(found)} imports of another command")
    sys.exit(1 if found else 0)
