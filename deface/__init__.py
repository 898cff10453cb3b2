"""deface: shadow-free 3D face textures by learning to decouple the lights (Huang et al., NeurIPS 2024)."""

from deface._version import __version__

__all__ = ["__version__", "load_fit"]


def load_fit(path, models_dir=None):
    """The fit in an output folder of ``deface fit`` as a :class:`deface.fit.output.FitOutput` (see
    :func:`deface.export.load.load_fit`); imported on first use so ``import deface`` stays light."""
    from deface.export.load import load_fit as load

    return load(path, models_dir)
