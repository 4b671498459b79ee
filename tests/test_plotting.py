"""Figures (``tire_learning_env.plotting``): each plot draws what it says (scaled to its units) and
``save_figure`` writes the PNG atomically (the studies' figures through the command: ``test_cli.py``)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from tire_learning_env import plotting as P

DEG = 180.0 / math.pi
PNG = b"\x89PNG\r\n\x1a\n"


def _png(path) -> bool:
    return path.read_bytes()[:8] == PNG and path.stat().st_size > 1000


def test_save_figure_writes_the_png_atomically_and_closes_the_figure(tmp_path):
    fig = plt.figure()
    assert P.save_figure(fig, None) is fig and plt.fignum_exists(fig.number)  # no path: nothing written
    path = tmp_path / "new" / "fig.png"
    fig.gca().plot([0, 1], [0, 1])
    assert P.save_figure(fig, path) is fig
    assert _png(path) and not plt.fignum_exists(fig.number)
    assert sorted(p.name for p in path.parent.iterdir()) == ["fig.png"]  # no temporary file left
    failing = plt.figure()

    def half_written(name, **kwargs):
        Path(name).write_bytes(PNG)  # a partial file, then the writer fails
        raise OSError("disk full")

    failing.savefig = half_written
    with pytest.raises(OSError, match="disk full"):
        P.save_figure(failing, path)
    assert _png(path) and sorted(p.name for p in path.parent.iterdir()) == ["fig.png"]  # old figure kept, temp removed
    plt.close(failing)


def test_true_vs_estimated_plots_scale_each_column_to_its_unit(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    true = np.column_stack([np.sin(t + k) for k in range(4)])
    est = 0.9 * true
    fig = P.plot_states(t, true, est, title="s", path=tmp_path / "states.png")
    assert _png(tmp_path / "states.png") and len(fig.axes) == 4
    for ax, scale, k in zip(fig.axes, (1.0, 1.0, DEG, DEG), range(4)):
        line_true, line_est = ax.get_lines()
        np.testing.assert_array_equal(line_true.get_ydata(), true[:, k] * scale)
        np.testing.assert_array_equal(line_est.get_ydata(), est[:, k] * scale)
    fig = P.plot_slip_angles(t, true[:, :2], est[:, :2], path=tmp_path / "slip.png")
    np.testing.assert_array_equal(fig.axes[1].get_lines()[0].get_ydata(), true[:, 1] * DEG)
    fig = P.plot_nonlinear_force(t, true[:, :2], est[:, :2], path=tmp_path / "force.png")
    np.testing.assert_array_equal(fig.axes[1].get_lines()[1].get_ydata(), est[:, 1])
    assert _png(tmp_path / "slip.png") and _png(tmp_path / "force.png")


def test_path_weights_and_force_slip_figures(tmp_path):
    t = np.linspace(0.0, 2.0, 21)
    fig = P.plot_path_and_steering({"x": t * 10, "y": np.sin(t)}, t, 0.01 * t, path=tmp_path / "path.png")
    np.testing.assert_allclose(fig.axes[1].get_lines()[0].get_ydata(), 0.01 * t * DEG)
    weights = np.arange(21 * 6, dtype=float).reshape(21, 6)
    fig = P.plot_weights(t, weights, 3, path=tmp_path / "weights.png")
    assert [len(ax.get_lines()) for ax in fig.axes] == [3, 3]
    np.testing.assert_array_equal(fig.axes[1].get_lines()[0].get_ydata(), weights[:, 3])  # rear axle: columns 3..5
    slip = np.radians(np.linspace(-4.0, 4.0, 50))
    fig = P.plot_force_slip_loop(slip, -1e5 * slip, steady=lambda a: -1e5 * a, path=tmp_path / "loop.png")
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["generated", "steady-state tire model"]
    fig = P.plot_tire_models({"linear": lambda a: -1e5 * a, "cubic": lambda a: -1e5 * a + 1e6 * a**3}, span_deg=6.0,
                             path=tmp_path / "models.png")  # fmt: skip
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_xdata()[[0, -1]], [-6.0, 6.0])
    for name in ("path", "weights", "loop", "models"):
        assert _png(tmp_path / f"{name}.png")


def test_tire_curves_mark_the_excited_range_and_the_bands(tmp_path):
    def curve(a, axle):
        return (-1e5 if axle == "front" else -2e5) * a

    fig = P.plot_tire_curves({"learned": curve}, curve, {"front": [-2.0, 3.0], "rear": [-1.0, 1.0]},
                             bands={"learned": lambda a, axle: np.full_like(a, 50.0)}, path=tmp_path / "tc.png")  # fmt: skip
    assert _png(tmp_path / "tc.png")
    for ax, (lo, hi) in zip(fig.axes, ([-2.0, 3.0], [-1.0, 1.0])):
        box = [p for p in ax.patches if isinstance(p, plt.Rectangle)]
        assert len(box) == 1 and box[0].get_x() == lo and box[0].get_width() == hi - lo
        span = 1.6 * max(abs(lo), abs(hi), 0.2)  # default half-width of the slip axis [deg]
        np.testing.assert_allclose(ax.get_lines()[0].get_xdata()[[0, -1]], [-span, span])
        assert len(ax.collections) == 1  # the +/- 2 sigma band
