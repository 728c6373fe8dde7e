"""The error hierarchy on the malformed files of the Rust tests (tests/malformed.rs and
tests/data/malformed): the table is read from tests/malformed.rs itself, so every case there
is a case here, with the same file, line, field and message."""
import re

import pytest

import cpm
from conftest import ROOT

CASE = re.compile(
    r'case\(\s*"(?P<file>[^"]+)",\s*(?P<on>\w+),\s*(?P<line>None|Some\((?P<l>\d+)\)),\s*'
    r'(?P<field>None|Some\("(?P<f>[^"]*)"\)),\s*"(?P<what>(?:[^"\\]|\\.)*)",?\s*\)',
    re.S,
)
DIR = "tests/data/malformed"
CUBE = "examples/paper_cubic.toml"
HEXAPOD = "examples/hexapod_66.toml"
GOOD = "tests/data/malformed/good.csv"


def cases():
    text = (ROOT / "tests" / "malformed.rs").read_text()
    table = text[text.index("const CASES: &[Case] = &["):]
    table = table[: table.index("\n];")]
    out = []
    for m in CASE.finditer(table):
        what = m["what"].encode().decode("unicode_escape")
        out.append((m["file"], m["on"], int(m["l"]) if m["l"] else None, m["f"], what))
    return out


CASES = cases()


def test_the_table_was_read():
    # tests/malformed.rs lists dozens of cases; a parse that found few would test little.
    assert len(CASES) >= 40, len(CASES)
    assert {c[1] for c in CASES} >= {"Data", "Tracker", "Toml", "Poses"}


@pytest.mark.parametrize("file,on,line,field,what", CASES, ids=[c[0] for c in CASES])
def test_malformed_input_raises_input_error(in_root, file, on, line, field, what):
    f = f"{DIR}/{file}"
    with pytest.raises(cpm.InputError) as e:
        if on == "Data":
            cpm.calibrate(CUBE, f)
        elif on == "Tracker":
            cpm.calibrate(HEXAPOD, f)
        elif on in ("Toml", "RobotThenData"):
            cpm.calibrate(f, GOOD)
        elif on == "Poses":
            cpm.compensate(CUBE, f)
        else:
            pytest.fail(f"unknown case kind {on}")
    err = e.value
    named = GOOD if on == "RobotThenData" else f
    want = named + (f":{line}" if line else "") + (f": field {field}" if field else "") \
        + f": {what}"
    assert str(err).startswith(want), f"\n got: {err}\nwant: {want}"
    assert isinstance(err, cpm.CpmError) and isinstance(err, ValueError)
    assert err.file == named
    assert err.line == line
    assert err.field == field


def test_usage_errors_are_usage_errors(in_root):
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(CUBE, GOOD, effects=["nosuch"])
    assert str(e.value).startswith("effects: ") and "nosuch" in str(e.value)
    with pytest.raises(cpm.UsageError):
        cpm.calibrate(CUBE, GOOD, robust="pink:3")
    with pytest.raises(cpm.UsageError):
        cpm.calibrate(CUBE, GOOD, sigma_um=-1.0)
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(CUBE, GOOD, no_such_option=1)
    assert "'no_such_option'" in str(e.value) and "--" not in str(e.value)


def test_every_command_names_a_bad_option(in_root):
    """Options by name (not an argument vector): an unknown option, a value of the wrong type
    or an unknown choice is a UsageError naming the option by its Python keyword, for the
    jobs as for calibrate."""
    with pytest.raises(cpm.UsageError) as e:
        cpm.validate(CUBE, CUBE, GOOD, no_such_option=1)
    assert "'no_such_option'" in str(e.value) and "validate takes" in str(e.value)
    with pytest.raises(cpm.UsageError) as e:
        cpm.design(CUBE, readings="many")
    assert "'readings'" in str(e.value)
    with pytest.raises(cpm.UsageError) as e:
        cpm.design(CUBE, criterion="z")
    assert "'criterion'" in str(e.value) and "`a`, `d`, `e`" in str(e.value)
    with pytest.raises(cpm.UsageError) as e:
        cpm.simulate(CUBE, random=12, measure="sound")
    assert "'measure'" in str(e.value) and "lengths" in str(e.value)
    with pytest.raises(cpm.UsageError) as e:
        cpm.identifiability(CUBE, circle=True, rank_rtol=float("nan"))
    assert "'rank_rtol'" in str(e.value) and "--" not in str(e.value)


def test_missing_data_file_is_an_io_error(in_root, tmp_path):
    with pytest.raises(cpm.CpmIOError) as e:
        cpm.calibrate(CUBE, tmp_path / "missing.csv")
    assert isinstance(e.value, OSError) and isinstance(e.value, cpm.CpmError)


def test_a_solver_that_stops_early_warns_and_says_so(in_root):
    with pytest.warns(cpm.CpmWarning, match="did not converge"):
        r = cpm.calibrate(CUBE, GOOD, max_iterations=1)
    assert not r.converged and r.trouble and "did not converge" in r.trouble
    assert any("did not converge" in w for w in r.warnings)


def test_exceptions_pickle_with_their_attributes():
    import pickle

    e = cpm.InputError("f.csv:3: field x_mm: bad", "f.csv", 3, "x_mm")
    e2 = pickle.loads(pickle.dumps(e))
    assert (e2.file, e2.line, e2.field, str(e2)) == ("f.csv", 3, "x_mm", str(e))
