"""primordia: feather-bud patterning by chemotaxis on porous, deforming, growing tissue."""

__version__ = "0.1.0"

from primordia.model import Model  # noqa: E402

__all__ = ["Model", "__version__"]
