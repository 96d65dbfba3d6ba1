"""A strip of frames of a scene, side by side (the docs' ``tests/figures/scene_*.png``).

    .venv/bin/python tests/tools/scene_strip.py skirt --frames 0 45 90 180 288 -o tests/figures/scene_skirt.png

Renders the scene once with ``clothsim render`` into a folder of every frame, then puts the chosen
frames side by side.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", help="scene file or bundled scene name")
    p.add_argument("--frames", type=int, nargs="+", required=True, help="frame numbers to show, in order")
    p.add_argument("--size", type=int, default=240, help="side of each frame in pixels (default 240)")
    p.add_argument("--shader", default="phong", help="look (default phong)")
    p.add_argument("-o", "--output", required=True, help="the strip, a .png")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "frames"
        subprocess.run([sys.executable, "-m", "clothsim", "render", args.scene, "--shader", args.shader, "--no-rest",
                        "--frames", str(max(args.frames)), "--every", "1", "--size", f"{args.size}x{args.size}",
                        "-o", f"{folder}/"], check=True)
        files = sorted(folder.glob("*.png"))
        images = [Image.open(files[f]) for f in args.frames]
        strip = Image.new("RGB", (args.size * len(images), args.size))
        for i, im in enumerate(images):
            strip.paste(im.convert("RGB"), (i * args.size, 0))
        strip.save(args.output)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
