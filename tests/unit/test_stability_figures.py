"""Figures of the stability analysis (primordia.analysis.figures): no global matplotlib state, whole PNGs."""

import subprocess
import sys

import pytest

from primordia.analysis.figures import dispersion_figure
from primordia.analysis.patterning import dispersion_relation
from primordia.core.errors import PrimordiaError
from primordia.physics.seed_parameters import seed_parameters


def test_importing_the_figures_leaves_the_matplotlib_backend_alone():
    probe = ("import matplotlib; import primordia.analysis.figures, primordia.core.pictures; "
             "print(matplotlib.get_backend())")
    chosen = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                            env={"MPLBACKEND": "svg", "PATH": ""}).stdout.strip()
    assert chosen == "svg"  # a user's (or a notebook's) backend is theirs


@pytest.fixture(scope="module")
def dispersion():
    return dispersion_relation(seed_parameters(), nk=24, coupled=False)


def test_a_dispersion_figure_is_a_whole_png_without_a_display(tmp_path, dispersion, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    path = tmp_path / "dispersion.png"
    dispersion_figure(dispersion, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["dispersion.png"]  # no temporary file left


def test_a_figure_that_cannot_be_saved_keeps_the_previous_one(tmp_path, dispersion, monkeypatch):
    path = tmp_path / "dispersion.png"
    path.write_bytes(b"previous")

    def die(self, target, **kwargs):
        with open(target, "wb") as partial:
            partial.write(b"\x89PNG half")
        raise OSError("disk full")

    monkeypatch.setattr("matplotlib.figure.Figure.savefig", die)
    with pytest.raises(OSError, match="disk full"):
        dispersion_figure(dispersion, path)
    assert path.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["dispersion.png"]


def test_no_figure_where_nothing_can_be_written(tmp_path, dispersion):
    (tmp_path / "taken").mkdir()
    with pytest.raises(PrimordiaError, match="is a directory"):
        dispersion_figure(dispersion, tmp_path / "taken")
