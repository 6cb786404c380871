"""sunshade as a Python library (docs/api.md): a config loaded and checked, a frame rendered into
arrays, a run rendered into a folder, the ground's irradiance, an eclipse's contacts. The
``sunshade`` command calls the same functions; an error is a ``SunshadeError`` whose text is the
line the command prints.

    import pipeline.api as sunshade
    config = sunshade.load_config("configs/eclipse.yaml")
    frame = sunshade.render_frame(config, 120)

May import: every other package but cli."""

from pipeline.api.functions import (
    Frame,
    Ground,
    eclipse,
    ground_irradiance,
    load_config,
    render_frame,
    render_run,
)
from pipeline.core.errors import SunshadeError

__all__ = ["SunshadeError", "Frame", "Ground", "load_config", "render_frame", "render_run", "ground_irradiance",
           "eclipse"]
