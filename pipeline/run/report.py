"""The run's report: the light of each frame as a CSV, its light curve and a contact sheet of its
frames, written into the run folder (docs/runs.md, "The report"). Read from index.json, which a
render writes as each frame is done, so a run still going or killed has its report too.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import csv
import itertools
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.core.errors import RunError
from pipeline.run.folder import INDEX_FILE, RUN_FILE

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["CSV_FILE", "CURVE_FILE", "SHEET_FILE", "SHEET_FRAMES", "COLUMNS", "SET_SUN", "frame_records", "rows",
           "write_csv", "contacts", "import_drawing", "write_light_curve", "write_contact_sheet", "write_report"]

CSV_FILE = "light.csv"
CURVE_FILE = "light-curve.png"
SHEET_FILE = "contact-sheet.png"
SHEET_FRAMES = 12
"""The contact sheet shows at most this many frames, evenly spread over the done ones. [count]"""

COLUMNS = ("frame", "time_s", "time_utc", "sun_elevation_deg", "sun_azimuth_deg", "S", "sun_lux", "sky_lux",
           "open_ground_lux", "ev100", "camera_ev100", "exposure_m2_per_kcd", "wb_r", "wb_g", "wb_b")
"""light.csv's columns: film time [s]; the sun's elevation and azimuth [degrees]; S [1]; the open
ground's horizontal illuminance from the sun and from the sky and both [lx]; what an incident
meter reads of it and the light the camera's exposure is set for [EV100]; that exposure
[m^2/kcd]; the white balance's gains [1]."""


def frame_records(folder: Path | str) -> list[dict[str, Any]]:
    """The done frames' records of a run folder, by frame.

    run.json's when it was written after index.json (a render ended there: the same records, in a
    file half the size), else those of index.json whose config hash is the one most of its frames
    have (a run going, or killed), else run.json's.

    Parameters
    ----------
    folder : pathlib.Path or str
        The run folder.

    Returns
    -------
    list of dict
        The frames' records (each with its ``frame``), in frame order.

    Raises
    ------
    RunError
        When the folder holds neither index.json nor run.json.
    """
    folder = Path(folder)
    entries = []
    try:
        if (folder / RUN_FILE).stat().st_mtime_ns >= (folder / INDEX_FILE).stat().st_mtime_ns:
            records = json.loads((folder / RUN_FILE).read_text()).get("frames")
            if isinstance(records, list) and records:
                return sorted((r for r in records if isinstance(r, dict) and "frame" in r), key=lambda r: r["frame"])
    except (OSError, ValueError, AttributeError):
        pass
    try:
        entries = list(json.loads((folder / INDEX_FILE).read_bytes()).get("frames", {}).values())
    except (OSError, ValueError, AttributeError):
        pass
    entries = [e for e in entries if isinstance(e, dict) and isinstance(e.get("record"), dict)]
    if entries:
        digest = collections.Counter(e.get("config_hash") for e in entries).most_common(1)[0][0]
        records = [e["record"] for e in entries if e.get("config_hash") == digest]
    else:
        try:
            records = json.loads((folder / RUN_FILE).read_text()).get("frames", [])
        except (OSError, ValueError, AttributeError):
            raise RunError(f"{folder}: no run here (neither {INDEX_FILE} nor {RUN_FILE} can be read)") from None
    return sorted((r for r in records if isinstance(r, dict) and "frame" in r), key=lambda r: r["frame"])


def rows(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """light.csv's rows (``COLUMNS``) of frame records.

    A value a record lacks is empty (frames rendered before the light was recorded).

    Parameters
    ----------
    records : iterable of dict
        Frame records (``frame_records``).

    Returns
    -------
    list of dict
        One row per record, keyed by COLUMNS; a missing value is None. Units as COLUMNS says:
        time_s [s], sun angles [deg], S [1], illuminances [lx], EV100, exposure [m^2/kcd], white
        balance gains [1].
    """
    out = []
    for record in records:
        light = record.get("light") or {}
        sun = record.get("sun") or {}
        total = (light["sun_lux"] + light["sky_lux"]) if "sun_lux" in light else None
        balance = light.get("white_balance") or [None] * 3
        out.append(dict(zip(COLUMNS, (
            record["frame"], light.get("time_s"), record.get("time_utc"), sun.get("elevation"), sun.get("azimuth"),
            record.get("sun_fraction"), light.get("sun_lux"), light.get("sky_lux"), total, light.get("ev100"),
            light.get("camera_ev100"), light.get("exposure"), *balance))))
    return out


def write_csv(folder: Path | str, table: Iterable[dict[str, Any]]) -> Path:
    """light.csv in ``folder`` (comma-separated, a header row; written atomically).

    Parameters
    ----------
    folder : pathlib.Path or str
        The run folder.
    table : iterable of dict
        Rows keyed by COLUMNS (``rows``); None is written empty.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = Path(folder) / CSV_FILE
    temporary = path.with_name(f".{CSV_FILE}.tmp")
    with open(temporary, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for row in table:
            writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    temporary.replace(path)
    return path


SET_SUN = 0.3
"""Below this elevation of its centre the sun's disc (0.27 degrees in radius) is not wholly up
and gives no direct light (docs/method.md, "Twilight and a sun at the horizon"). [deg]"""


def contacts(table: Iterable[dict[str, Any]]) -> list[tuple[str, float]]:
    """An eclipse's contacts as seen in S: only those the frames show.

    C1 is the first frame with S below 1 after one at 1, C2 the first with S at 0, C3 the last at
    0, C4 the first back at 1. Frames dimmed by clouds look the same to S: the caller marks
    contacts only for a run with a moon. Frames whose sun is below SET_SUN take no part: their S
    is 0 because the sun has set (civil twilight), not because the moon covers it.

    Parameters
    ----------
    table : iterable of dict
        light.csv's rows (``rows``), in frame order: time_s [s], S [1], sun_elevation_deg [deg].

    Returns
    -------
    list of tuple of (str, float)
        (label, film time [s]) of each contact found, in the order found.
    """
    points = [(r["time_s"], r["S"]) for r in table if r["time_s"] is not None and r["S"] is not None
              and (r.get("sun_elevation_deg") is None or r["sun_elevation_deg"] > SET_SUN)]
    found, full, dark = [], 1.0 - 1e-6, 1e-6
    for (t0, s0), (t1, s1) in itertools.pairwise(points):
        if s0 >= full > s1:
            found.append(("C1", t1))
        if s0 > dark >= s1:
            found.append(("C2", t1))
        if s0 <= dark < s1:
            found.append(("C3", t0))
        if s0 < full <= s1:
            found.append(("C4", t1))
    return found


def import_drawing() -> None:
    """Import what ``write_light_curve`` draws with (matplotlib's Figure and its Agg canvas: 0.8 s
    of a 1.2 s report, more where matplotlib has not yet built its font cache), so that a render
    can import it while its frames render and write its report without that wait. Any error is
    left to ``write_light_curve``.
    """
    with contextlib.suppress(Exception):
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
        from matplotlib.figure import Figure  # noqa: F401


def write_light_curve(folder: Path | str, table: Iterable[dict[str, Any]], *, eclipse: bool,
                      name: str | None = None) -> Path | None:
    """light-curve.png: the open ground's illuminance and S against film time.

    The illuminance from the sun, the sky and both on a log axis [lx] with the light the camera's
    exposure is set for, S on a second axis, the incident meter's and the camera's EV100 below,
    against film time [s]; an eclipse's contacts marked (``contacts``).

    Parameters
    ----------
    folder : pathlib.Path or str
        The run folder, where the file is written (atomically).
    table : list of dict
        light.csv's rows (``rows``).
    eclipse : bool
        Whether to mark the contacts (a run with a moon).
    name : str, optional
        The run's name for the title; default the folder's.

    Returns
    -------
    pathlib.Path or None
        The file written; None when no frame has its light recorded.
    """
    table = [r for r in table if r["time_s"] is not None]
    if not table:
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure  # not pyplot: a third less to import, no global state

    t = [r["time_s"] for r in table]
    floor = 1e-3  # lx: a dark sun is drawn at the axis' foot, not dropped from a log axis
    fig = Figure(figsize=(8, 5.5))
    FigureCanvasAgg(fig)
    ax, ev = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1.4))
    fig.subplots_adjust(left=0.1, right=0.9, top=0.94, bottom=0.09, hspace=0.08)
    for key, label, style in (("open_ground_lux", "open ground (sun + sky)", "k-"),
                              ("sun_lux", "sun", "-"), ("sky_lux", "sky", "-")):
        ax.plot(t, [max(r[key], floor) for r in table], style, label=label, lw=1.5)
    metered = [math.pi / r["exposure_m2_per_kcd"] * 1000.0 if r["exposure_m2_per_kcd"] else None for r in table]
    ax.plot(t, metered, "--", color="0.4", label="camera's exposure set for", lw=1.2)
    ax.set_yscale("log")
    lit = [v for r in table for v in (r["open_ground_lux"], r["sky_lux"]) if v and v > 0]
    if lit:
        ax.set_ylim(max(min(lit) / 3, floor), max(lit) * 3)
    ax.set_ylabel("horizontal illuminance [lx]")
    ax.grid(True, which="both", alpha=0.25)
    share = ax.twinx()
    share.plot(t, [r["S"] for r in table], color="tab:red", lw=1.2, label="S")
    share.set_ylim(-0.02, 1.05)
    share.set_ylabel("S, the sun's fraction", color="tab:red")
    handles = ax.get_legend_handles_labels()[0] + share.get_legend_handles_labels()[0]
    ax.legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.85)
    ev.plot(t, [r["ev100"] for r in table], "k-", label="incident meter", lw=1.2)
    ev.plot(t, [r["camera_ev100"] for r in table], "--", color="0.4", label="camera", lw=1.2)
    ev.set_ylabel("EV100")
    ev.set_xlabel("film time [s]")
    ev.grid(True, alpha=0.25)
    ev.legend(loc="lower left", fontsize=8)
    for label, when in contacts(table) if eclipse else ():
        for axis in (ax, ev):
            axis.axvline(when, color="tab:purple", lw=0.8, ls=":")
        ax.text(when, 1.0, f" {label}", transform=ax.get_xaxis_transform(), va="top", fontsize=8,
                color="tab:purple")
    first, last = table[0].get("time_utc"), table[-1].get("time_utc")
    title = f"{name or Path(folder).name}: {len(table)} frames"
    if first and last:
        title += f", {first[:19]} to {last[11:19]} UTC"
    ax.set_title(title, fontsize=10)
    path = Path(folder) / CURVE_FILE
    temporary = path.with_name(f".{CURVE_FILE}.tmp.png")
    fig.savefig(temporary, dpi=100, metadata={"Software": None})
    temporary.replace(path)
    return path


def write_contact_sheet(folder: Path | str, records: Iterable[dict[str, Any]], *, count: int = SHEET_FRAMES,
                        width: int = 240) -> Path | None:
    """contact-sheet.png: the done frames' PNGs, evenly spread, in rows of four.

    Each thumbnail is labelled with its frame number and S.

    Parameters
    ----------
    folder : pathlib.Path or str
        The run folder, where the frames' PNGs are read and the sheet written (atomically).
    records : iterable of dict
        Frame records (``frame_records``), each with its ``file`` stem.
    count : int, optional
        Most frames shown [count].
    width : int, optional
        Width of each thumbnail [px].

    Returns
    -------
    pathlib.Path or None
        The file written; None without a frame's PNG.
    """
    from PIL import Image, ImageDraw

    found = [(r, Path(folder) / f"{r['file']}.png") for r in records if "file" in r]
    found = [(r, p) for r, p in found if p.is_file()]
    if not found:
        return None
    if len(found) > count:
        found = [found[round(i * (len(found) - 1) / (count - 1))] for i in range(count)]
    def thumbnail(png):
        with Image.open(png) as image:
            image = image.convert("RGB")
            height = max(1, round(image.height * width / image.width))
            return image.resize((width, height), Image.Resampling.BILINEAR)

    with concurrent.futures.ThreadPoolExecutor(4) as pool:  # PNG decoding lets go of the GIL
        thumbs = list(zip((r for r, _ in found), pool.map(thumbnail, [p for _, p in found])))
    across, gap, label = min(4, len(thumbs)), 4, 14
    cell = (width, max(t.height for _, t in thumbs) + label)
    down = math.ceil(len(thumbs) / across)
    sheet = Image.new("RGB", (across * (cell[0] + gap) + gap, down * (cell[1] + gap) + gap), (32, 32, 32))
    draw = ImageDraw.Draw(sheet)
    for i, (record, thumb) in enumerate(thumbs):
        x, y = gap + (i % across) * (cell[0] + gap), gap + (i // across) * (cell[1] + gap)
        sheet.paste(thumb, (x, y))
        s = record.get("sun_fraction")
        draw.text((x + 2, y + thumb.height + 1), f"{record['frame']}" + (f"   S = {s:.3f}" if s is not None else ""),
                  fill=(230, 230, 230))
    path = Path(folder) / SHEET_FILE
    temporary = path.with_name(f".{SHEET_FILE}.tmp.png")
    sheet.save(temporary, format="PNG")
    temporary.replace(path)
    return path


def write_report(folder: Path | str) -> list[Path]:
    """light.csv, light-curve.png and contact-sheet.png of the run in ``folder`` (docs/runs.md, "The report").

    Made from its done frames (``frame_records``).

    Parameters
    ----------
    folder : pathlib.Path or str
        The run folder, as in ``frame_records``.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    RunError
        When the folder holds no run.
    """
    folder = Path(folder)
    records = frame_records(folder)
    table = rows(records)
    written = [write_csv(folder, table)]
    eclipse = any("moon" in r for r in records)
    with concurrent.futures.ThreadPoolExecutor(1) as pool:  # the sheet's PNGs decode meanwhile
        sheet = pool.submit(write_contact_sheet, folder, records)
        name = str(records[0].get("file", "")).rsplit(".", 1)[0] if records else None  # NAME.0000
        curve = write_light_curve(folder, table, eclipse=eclipse, name=name or None)
        written += [p for p in (curve, sheet.result()) if p is not None]
    return written
