"""A constant-luminance overcast sky: the example of a sky model added in one module and one line
of ``vocabulary.SKIES`` (docs/design.md, "Models plug in"). Every direction has the luminance
``sky.luminance`` [kcd/m^2] in white light; there is no sun."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.config.settings import SkyConfig
from pipeline.sky.models import ConstantSky

__all__ = ["OvercastModel"]


@dataclass(frozen=True)
class OvercastModel(ConstantSky):
    """A sky of luminance ``sky.luminance`` [kcd/m^2] in every direction, white, no sun.

    Parameters
    ----------
    config : SkyConfig
        The config's ``sky`` section; its ``params`` hold ``luminance``.
    """

    config: SkyConfig

    @property
    def radiance(self) -> np.ndarray:
        """The luminance in each linear Rec.709 channel (3,) [kcd/m^2]."""
        return np.full(3, dict(self.config.params)["luminance"])
