import os

import matplotlib
import pytest

matplotlib.use("Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")


class PythonOnlyPlant:
    """The same plant without its compiled parameters: forces the Python tick loops
    (``Simulator.advance`` and the highway ego loop) instead of the compiled ones."""

    def __init__(self, plant):
        self._p = plant
        self.vehicle = plant.vehicle

    @property
    def state(self):
        return self._p.state

    def reset(self, xi=None):
        self._p.reset(xi)

    def step(self, *args):
        return self._p.step(*args)

    def output(self):
        return self._p.output()


@pytest.fixture
def python_only_plant():
    """:class:`PythonOnlyPlant`, the wrapper that sends a plant through the Python loops."""
    return PythonOnlyPlant
