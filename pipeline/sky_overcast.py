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
        """The sky's radiance: the luminance in each linear Rec.709 channel.

        Returns
        -------
        ndarray, shape (3,)
            Radiance [kcd/m^2].
        """
        return np.full(3, dict(self.config.params)["luminance"])

    def discs(self, fraction: float):
        """See ``skies.SkyModel.discs``.

        Parameters
        ----------
        fraction : float
            The frame's place in the animation, 0 to 1 [1] (not used).

        Returns
        -------
        tuple
            (None, None, None): no time, no sun, no moon.
        """
        return None, None, None

    def at(self, scene, *, metering: bool = False):
        """See ``skies.SkyModel.at``.

        Parameters
        ----------
        scene : scene.Scene or None
            The frame's scene (not used).
        metering : bool
            For an exposure meter (not used).

        Returns
        -------
        sky.UniformSky
            ``radiance`` [kcd/m^2] in every direction.
        """
        return skylib.UniformSky(self.radiance)

    def clear_light(self, sun):
        """See ``skies.SkyModel.clear_light``.

        Parameters
        ----------
        sun : sky.SunDisc or None
            The sun (not used).

        Returns
        -------
        tuple
            (None, the sky's horizontal irradiance (3,), pi times the radiance [klx]).
        """
        return None, np.pi * self.radiance

    def check(self) -> None:
        """See ``skies.SkyModel.check``: nothing to read."""
        pass
