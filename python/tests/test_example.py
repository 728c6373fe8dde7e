"""The example of examples/python runs as written (its assertions hold)."""
import runpy
import sys

from conftest import ROOT


def test_example_script_runs(tmp_path, monkeypatch, capsys):
    script = ROOT / "examples" / "python" / "calibrate.py"
    monkeypatch.setattr(sys, "argv", [str(script), str(tmp_path / "out")])
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert "the paper's circle: rank" in out
    assert "effects added:" in out
    for f in ("cal/report.html", "refined/calibrated.toml", "validation/validation.json",
              "commands.csv", "joints.ini", "data.csv", "held_out.csv"):
        assert (tmp_path / "out" / f).exists(), f
    assert (tmp_path / "out" / "data.csv").read_text().startswith("# simulated by cpm")
