"""The viewer layouts shipped with the package (``tofpose/io/interop/viewers/``), and
the ones ``tofpose export mcap`` writes beside a file (docs/interop.md).

- ``foxglove-layout.json``: a Foxglove layout (the app's "Import from file..." in the
  layout menu): a 3-D panel in the ``camera`` frame (the camera's frustum, the target's
  frames, the reflectors, the trail of the target's origin, a 1 m grid), the gray image
  with the overlay, the distance image, plots of the position, attitude and turntable,
  and the estimate's raw messages. Every topic and field it names is one the export
  writes (``tests/tofpose/io/interop/test_viewers.py``).
- ``tofpose.rbl``: the Rerun blueprint of ``rerun_blueprint`` for the application id
  ``tofpose``, that of ``tofpose export rrd`` (whose files also carry it embedded);
  ``python -m tofpose.io.interop.viewers`` writes it again.
"""

from __future__ import annotations

import shutil
from pathlib import Path

VIEWERS_DIR = Path(__file__).with_name("viewers")
FOXGLOVE_LAYOUT = VIEWERS_DIR / "foxglove-layout.json"
RERUN_BLUEPRINT = VIEWERS_DIR / "tofpose.rbl"
FOXGLOVE_SUFFIX = ".foxglove-layout.json"


def viewer_paths(mcap_path: str | Path) -> tuple[Path, Path]:
    """Where the layouts go beside the MCAP export ``mcap_path``: ``REC.mcap`` ->
    ``REC.foxglove-layout.json`` and ``REC.rbl``."""
    out = Path(mcap_path)
    return out.with_name(out.stem + FOXGLOVE_SUFFIX), out.with_name(out.stem + ".rbl")


def write_viewers(mcap_path: str | Path) -> list[Path]:
    """The shipped Foxglove layout and a Rerun blueprint beside the MCAP export
    ``mcap_path`` (Foxglove profile); returns what was written. The blueprint is built
    for the application id Rerun gives that file (``mcap_application_id``), without
    the time series an MCAP cannot fill; without rerun-sdk installed, only the layout."""
    layout, blueprint = viewer_paths(mcap_path)
    shutil.copyfile(FOXGLOVE_LAYOUT, layout)
    try:
        from tofpose.io.interop.rerun_blueprint import mcap_application_id, save_blueprint

        save_blueprint(blueprint, mcap_application_id(mcap_path), series=False)
    except ImportError:  # rerun-sdk is optional: Foxglove's layout alone
        return [layout]
    return [layout, blueprint]


if __name__ == "__main__":  # the shipped blueprint, built again (needs rerun-sdk)
    from tofpose.io.interop.rerun_blueprint import save_blueprint

    print(save_blueprint(RERUN_BLUEPRINT))
