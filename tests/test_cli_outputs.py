"""Every command that writes: an unusable --out is one line and exit 2, and nothing is written."""

from pathlib import Path

import pytest

from twin.cli import main

FRAME = Path(__file__).resolve().parent / "data"


def commands(out: str) -> dict[str, list[str]]:
    """Each writing command with ``out`` as its output path and otherwise valid arguments."""
    model = str(next(FRAME.rglob("*.npz"), FRAME / "none.npz"))
    image = str(next(FRAME.rglob("*.png"), FRAME / "none.png"))
    return {
        "survey": ["survey", "--out", out, "--quiet", "--set", "run.rerun=off"],
        "montecarlo": ["montecarlo", "--out", out, "--trials", "1", "--quiet"],
        "batch-survey": ["batch-survey", "--out", out, "--runs", "1", "--quiet"],
        "detect": ["detect", "--model", model, image, "--out", out],
        "train": ["train", "--name", "x", "--images", str(FRAME), "--out", out],
        "sim snapshot": ["sim", "snapshot", "--pose", "2.25,2.5,90", "--out", out],
        "sim contact-sheet": ["sim", "contact-sheet", "--out", out],
    }


@pytest.fixture
def a_file(tmp_path):
    path = tmp_path / "a_file"
    path.write_text("mine")
    return path


@pytest.mark.parametrize("command", sorted(commands("x")))
@pytest.mark.parametrize("where", ["inside a file", "under /proc"])
def test_an_unusable_out_is_one_line_and_writes_nothing(command, where, a_file, capsys):
    out = a_file / "sub" / "out.png" if where == "inside a file" else "/proc/twin-test/out.png"
    code = main(commands(str(out))[command])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("twin ")
    assert "Traceback" not in err and str(out) in err
    assert a_file.read_text() == "mine"
    assert sorted(p.name for p in a_file.parent.iterdir()) == ["a_file"]
