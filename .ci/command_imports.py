#!/usr/bin/env python3
"""No command of the `cpm` command line imports another command's module (issue 36): what two
commands share lives in the workflow crate (crates/cpm-workflow) or in `src/cli/common.rs`
(shared arguments). A command is a module of src/cli named in its `Command` enum: `X.rs` or the
folder `X/`.

In the workflow crate (issue 59), no job imports another job's staging: a job is a module of
crates/cpm-workflow/src that a command runs (WORKFLOW_JOBS), and its staging is its `stage_*`
functions; what two jobs stage alike lives in a shared module (`staging`, `load`). Exit 1
naming each offending line."""
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


WORKFLOW = pathlib.Path("crates/cpm-workflow/src")
WORKFLOW_JOBS = [
    "compensate", "design", "export", "fit", "gauges", "identifiability", "plan", "refine",
    "simulate", "validate",
]


def workflow_files(job, root):
    f = root / f"{job}.rs"
    return [f] if f.exists() else sorted((root / job).rglob("*.rs"))


def staging_offences(job, path, jobs):
    """Lines of `path` (a module of `job`) naming another job's `stage_*` function, by path
    (`crate::fit::stage_figures`) or in a `use crate::fit::{..., stage_figures}`."""
    others = "|".join(j for j in jobs if j != job)
    by_path = re.compile(r"\bcrate::(" + others + r")::(stage_\w+)")
    by_use = re.compile(r"\buse\s+crate::(" + others + r")::\{([^}]*)\}")
    text = path.read_text()
    for n, line in enumerate(text.splitlines(), 1):
        code = line.split("//")[0]
        m = by_path.search(code)
        if m:
            yield f"{path}:{n}: the job `{job}` imports the staging of `{m.group(1)}`: {m.group(2)}"
    for m in by_use.finditer(text):
        names = [x.strip() for x in m.group(2).split(",") if x.strip().startswith("stage_")]
        if names:
            n = text[: m.start()].count("\n") + 1
            yield f"{path}:{n}: the job `{job}` imports the staging of `{m.group(1)}`: {', '.join(names)}"


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
        wf = pathlib.Path(d) / "wf"
        wf.mkdir()
        (wf / "fit.rs").write_text("pub fn stage_figures() {}\n")
        (wf / "refine.rs").write_text(
            "use crate::fit::{Inputs,\n stage_figures};\nfn f() { crate::fit::stage_residuals(); }\n"
        )
        (wf / "validate.rs").write_text("use crate::staging::stage_figures; // shared\n")
        found = [
            o for j in ["fit", "refine", "validate"] for f in workflow_files(j, wf)
            for o in staging_offences(j, f, ["fit", "refine", "validate"])
        ]
        assert len(found) == 2 and all("`refine` imports the staging of `fit`" in o for o in found), found


if __name__ == "__main__":
    self_test()
    found = [o for c in COMMANDS for f in files_of(c) for o in offences(c, f)]
    for o in found:
        print(o)
    print(f"{len(COMMANDS)} commands ({', '.join(COMMANDS)}), {len(found)} imports of another command")
    staged = [
        o for j in WORKFLOW_JOBS for f in workflow_files(j, WORKFLOW)
        for o in staging_offences(j, f, WORKFLOW_JOBS)
    ]
    for o in staged:
        print(o)
    print(f"{len(WORKFLOW_JOBS)} workflow jobs, {len(staged)} imports of another job's staging")
    sys.exit(1 if found or staged else 0)
