"""The eclipse finder (``sunshade eclipses``) against JPL's DE421, eclipse by eclipse.

    python benchmarks/accuracy_eclipse_finder.py

For every site and span of tests/test_eclipse_finder.py (``SITES``, ``SPANS``): each eclipse the
finder sees, its contacts minus the same contacts solved in the test's independent DE421
computation (jplephem and de421, the test extra) [s], its greatest obscuration against DE421's
over +-2 minutes of its maximum, and the two Delta T used (the reference's, ours) [s]: the table
of docs/accuracy.md, "The eclipse finder against DE421".
"""

from __future__ import annotations

import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_eclipse_finder import DELTA_T, SITES, SPANS, reference_gaps, reference_root

from pipeline.sky.eclipse_search import find_eclipses
from pipeline.sky.ephemeris import Site, delta_t


def main() -> None:
    print("| site | date | seen | contacts, finder - DE421 [s] | obscuration | DE421 | difference "
          "| Delta T ref. / ours [s] |")
    print("|---|---|---|---|---|---|---|---|")
    worst_contact = worst_cover = 0.0
    for name, where in SITES.items():
        first, last = SPANS[name]
        site = Site.from_degrees(*where)
        for found in find_eclipses(site, datetime(first, 1, 1, tzinfo=UTC), datetime(last + 1, 1, 1, tzinfo=UTC)):
            gaps = []
            for key, when in found.contacts.items():
                if when is None:
                    continue
                gap = (when - reference_root(where, when, "external" if key in ("C1", "C4") else "internal"))
                gaps.append(f"{key} {gap.total_seconds():+.2f}")
                worst_contact = max(worst_contact, abs(gap.total_seconds()))
            times = [found.maximum + timedelta(seconds=k) for k in range(-120, 121)]
            cover = float(np.max(reference_gaps(where, times)["covered"]))
            worst_cover = max(worst_cover, abs(found.obscuration - cover))
            print(f"| {name} | {found.maximum:%Y-%m-%d} | {found.seen} | {', '.join(gaps)} | "
                  f"{found.obscuration:.5f} | {cover:.5f} | {found.obscuration - cover:+.1e} | "
                  f"{DELTA_T[(found.maximum.year, found.maximum.month)]} / {delta_t(found.maximum):.2f} |", flush=True)
    print(f"largest contact difference {worst_contact:.2f} s; largest obscuration difference {worst_cover:.1e}")


if __name__ == "__main__":
    main()
