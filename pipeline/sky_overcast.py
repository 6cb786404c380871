"""A constant-luminance overcast sky: the example of a sky model added in one module and one line
of ``vocabulary.SKIES`` (docs/design.md, "Models plug in"). Every direction has the luminance
``sky.luminance`` [kcd/m^2] in white light; there is no sun."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sky as skylib
from .settings import SkyConfig

__all__ = ["OvercastModel"]


@dataclass(frozen=True)
class OvercastModel:
    """A sky of luminance ``sky.luminance`` [kcd/m^2] in every direction, white, without a sun.

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section; ``params`` holds ``luminance``.
    """

    config: SkyConfig

    @property
    def radiance(self) -> np.ndarray:
        """The sky's radiance (3,) [kcd/m^2]: the luminance in each linear Rec.709 channel."""
        return np.full(3, dict(self.config.params)["luminance"])

    def discs(self, fraction: float):
        return None, None, None

    def at(self, scene, *, metering: bool = False):
        return skylib.UniformSky(self.radiance)

    def clear_light(self, sun):
        return None, np.pi * self.radiance

    def check(self) -> None:
        pass
