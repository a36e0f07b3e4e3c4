"""Screenshot the Rerun viewer on a recording, headless (how docs/img/rerun_viewer.png is made).

    python scripts/rerun_screenshot.py results/demo.rrd docs/img/rerun_viewer.png --step 64

Needs the viewer extra (``rerun-sdk``, whose wheel carries the ``rerun`` viewer binary, found
next to this Python) and a Vulkan adapter: on a machine without a GPU, Mesa's software
rasterizer (Debian: ``apt-get install mesa-vulkan-drivers``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path, help="the recording (.rrd)")
    parser.add_argument("png", type=Path, help="the screenshot to write (.png)")
    parser.add_argument("--step", type=int, default=None, help="show this step of the 'step' "
                        "timeline (default: the end)")
    parser.add_argument("--wait", type=float, default=8.0, help="seconds to let it load")
    parser.add_argument("--port", type=int, default=9877, help="the viewer's gRPC port")
    args = parser.parse_args()
    if not args.rrd.is_file():
        raise SystemExit(f"error: no such recording: {args.rrd}")
    from localization.workflows.rerun_log import require_rerun

    require_rerun()
    from rerun.experimental import ViewerClient

    os.environ["PATH"] = str(Path(sys.executable).parent) + os.pathsep + os.environ["PATH"]
    viewer = ViewerClient.spawn(headless=True, hide_welcome_screen=True, port=args.port)
    try:
        viewer.open(str(args.rrd.resolve()))
        time.sleep(args.wait)
        if args.step is not None:
            viewer.set_time("step", sequence=args.step)
            time.sleep(2.0)
        args.png.parent.mkdir(parents=True, exist_ok=True)
        viewer.save_screenshot(str(args.png.resolve()))
    finally:
        viewer.quit()
    print(args.png)


if __name__ == "__main__":
    main()
