"""Every value option of ``nearopt plan`` given a wrong value, one at a time: the command
either plans or answers with exit code 2 and one line on stderr — no traceback, no warning
printed on the way, no file left behind."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from console import run_cli

BASE = {
    "--robot": ["two_link"],
    "--q0": ["45", "-90"],
    "--qe": ["-90", "0"],
    "--grid": ["20"],
    "--max-iterations": ["1"],
}
FLAGS = ["--deg", "--quiet"]
OPTIONS = {  # option → how many values it takes here
    "--grid": 1,
    "--max-iterations": 1,
    "--time-limit": 1,
    "--rate": 1,
    "--beta": 1,
    "--weights": 2,
    "--effort-limit": 2,
    "--velocity-limit": 2,
    "--velocity-scale": 1,
    "--acceleration-limit": 2,
    "--margin": 1,
    "--goal-pose": 3,
    "--via": 2,
    "--lock-at": 1,
    "--frame": 1,
    "--tip": 1,
    "--lock": 1,
    "--method": 1,
    "--q0": 2,
    "--qe": 2,
}
BAD = ["-1", "0", "nan", "-inf", "1e300", "abc", "", "1e-300"]


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("option", list(OPTIONS))
def test_a_wrong_option_value_is_one_line(option: str, bad: str, tmp_path: Path) -> None:
    given = dict(BASE)
    given[option] = [bad] * OPTIONS[option]
    args = [word for key, values in given.items() for word in (key, *values)] + FLAGS
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        done = run_cli("plan", *args, cwd=tmp_path)
    assert not [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert "Traceback" not in done.stderr + done.stdout
    lines = done.stderr.strip().splitlines()
    if done.returncode == 0:
        assert not lines, done.stderr  # no warning from a library on the way
    else:
        assert done.returncode == 2, done.stderr
        assert len(lines) == 1 and lines[0].startswith("nearopt: error: "), done.stderr
    assert list(tmp_path.iterdir()) == []


def test_an_abbreviated_option_is_refused_as_a_batch_refuses_it(tmp_path: Path) -> None:
    """``--bet 0.03`` was read as ``--beta 0.03`` on the command line while a batch's motion
    with ``"bet"`` was refused: one request model, one spelling of each option."""
    args = [word for key, values in BASE.items() for word in (key, *values)] + FLAGS
    done = run_cli("plan", *args, "--bet", "0.03", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == "nearopt: error: unrecognized arguments: --bet 0.03"
    assert run_cli("plan", *args, "--beta", "0.03", cwd=tmp_path).returncode == 0
