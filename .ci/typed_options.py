#!/usr/bin/env python3
"""The workflow's option structs hold typed values, not command-line strings (issue 59,
"Typed from end to end"): no field `effects`, `robust`, `tolerance`, `tolerances` or `hold` of a
`pub struct ...Options` in crates/cpm-workflow/src is a `String`, `Option<String>` or
`Vec<String>` (the values are parsed once at the edge: cpm_workflow::options). Exit 1 naming
each offending field. `--self-test` checks the checker on made-up sources."""
import pathlib
import re
import sys

ROOT = pathlib.Path("crates/cpm-workflow/src")
FIELDS = {"effects", "robust", "tolerance", "tolerances", "hold"}
STRINGS = {"String", "Option<String>", "Vec<String>"}
STRUCT = re.compile(r"\bpub\s+struct\s+(\w*Options)\b[^{;]*\{")
FIELD = re.compile(r"^(?:pub(?:\([^)]*\))?\s+)?(\w+)\s*:\s*(.+)$", re.S)
ATTRIBUTE = re.compile(r"#\[[^\]]*\]")


def code_of(text):
    """The text without its `//` comments (line numbers kept)."""
    return "\n".join(line.split("//")[0] for line in text.splitlines())


def body(text, start):
    """The text of the braces that open just before `start`."""
    depth = 1
    i = start
    while i < len(text) and depth:
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        i += 1
    return text[start:i - 1]


def fields(text):
    """The fields of a struct's body: (offset, name, type), split at its top-level commas."""
    depth, begin = 0, 0
    for i, c in enumerate(text + ","):
        if not (c == ">" and text[i - 1:i] == "-"):  # `->` closes nothing
            depth += {"<": 1, "(": 1, "[": 1, ">": -1, ")": -1, "]": -1}.get(c, 0)
        if c == "," and depth == 0:
            piece = ATTRIBUTE.sub(lambda m: " " * len(m.group(0)), text[begin:i])
            stripped = piece.lstrip()
            f = FIELD.match(stripped)
            if f:
                yield begin + len(piece) - len(stripped), f.group(1), f.group(2)
            begin = i + 1


def offences(path, text):
    code = code_of(text)
    for m in STRUCT.finditer(code):
        for offset, name, ty in fields(body(code, m.end())):
            ty = re.sub(r"\s+", "", ty).replace("std::string::String", "String")
            if name in FIELDS and ty in STRINGS:
                line = code.count("\n", 0, m.end() + offset) + 1
                yield (f"{path}:{line}: {m.group(1)}::{name} is `{ty}`: a command-line "
                       "string; make it a typed value parsed at the edge (cpm_workflow::options)")


def check(root):
    found = []
    structs = 0
    for path in sorted(root.rglob("*.rs")):
        text = path.read_text()
        structs += len(STRUCT.findall(code_of(text)))
        found += offences(path, text)
    return structs, found


def self_test():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        root = pathlib.Path(d)
        (root / "a.rs").write_text(
            "/// Options.\n#[derive(Debug)]\npub struct FitOptions {\n"
            "    /// The effects.\n    pub effects: Option<String>,\n"
            "    pub robust: Option<Loss>,\n    pub tolerance: Vec<Tolerance>,\n"
            "    pub hold: Vec< String >,\n    pub noise: Option<String>,\n}\n"
            "pub struct Report {\n    pub hold: Vec<String>,\n}\n"
        )
        (root / "b.rs").write_text(
            "pub struct DesignOptions { pub f: Box<dyn Fn(u8) -> u8>, pub robust: String,"
            " #[serde(default)] pub(crate) tolerances: BTreeMap<String, f64> }\n"
            "// pub struct OldOptions { pub effects: String }\n"
        )
        structs, found = check(root)
        assert structs == 2, structs
        assert len(found) == 3, found
        assert "a.rs:5: FitOptions::effects is `Option<String>`" in found[0], found
        assert "FitOptions::hold is `Vec<String>`" in found[1], found
        assert "DesignOptions::robust is `String`" in found[2], found


if __name__ == "__main__":
    self_test()
    if "--self-test" in sys.argv[1:]:
        print("typed_options.py: self-test passed")
        sys.exit(0)
    structs, found = check(ROOT)
    for o in found:
        print(o)
    print(f"{structs} option structs in {ROOT}, {len(found)} command-line strings for "
          "effects, robust losses, tolerances or holds")
    sys.exit(1 if found or structs == 0 else 0)
