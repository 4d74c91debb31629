"""Render a short camera fly-through to numbered EXR and PNG files.

    python examples/flythrough.py                          # Sibenik, 12 frames, 320x240, 4 spp
    python examples/flythrough.py sponza --frames 48 --size 640x360 --threads 2 -o frames/
    ffmpeg -framerate 24 -i frames/frame_%04d.png flythrough.mp4    # a video, if you have ffmpeg

The camera glides from the scene's own viewpoint halfway toward the point it looks at,
turning a little to the side.  One Pipeline renders every frame: the BVH is built once
and only the scene's camera changes between frames.  Each frame is written whole or not
at all, as ``frame_0000.exr`` (linear) and ``frame_0000.png`` (a preview).
"""
import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

import raysort


def camera_path(camera, frames, forward=0.5, turn_degrees=20.0):
    """``frames`` cameras along the first ``forward`` of the way from the eye to look_at,
    the view turning by up to ``turn_degrees`` about the up axis and back."""
    eye, target = np.array(camera.eye), np.array(camera.look_at)
    up = np.array(camera.up) / np.linalg.norm(camera.up)
    for i in range(frames):
        s = i / max(frames - 1, 1)
        position = eye + forward * s * (target - eye)
        view = target - position
        angle = math.radians(turn_degrees) * math.sin(math.pi * s)
        # rotate the view direction about the up axis (Rodrigues' formula)
        view = (view * math.cos(angle) + np.cross(up, view) * math.sin(angle)
                + up * np.dot(up, view) * (1 - math.cos(angle)))
        yield dataclasses.replace(camera, eye=tuple(position), look_at=tuple(position + view))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--size", default="320x240", help="WIDTHxHEIGHT (320x240)")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("-o", "--output", default="frames", help="output folder (frames/)")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))

    pipe = raysort.Pipeline(args.scene, threads=args.threads)
    start_camera = pipe.scene.camera
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    for i, camera in enumerate(camera_path(start_camera, args.frames)):
        pipe.scene.camera = camera
        # seed = frame number: the noise changes from frame to frame instead of sticking
        # to the screen; any fixed seed would make a bit-identical frame again
        result = pipe.render(width, height, args.spp, seed=i)
        path = out / f"frame_{i:04d}.exr"
        result.write(path)                       # + frame_XXXX.png
        print(f"{path}  {result.stats.wall_seconds:.2f} s  "
              f"{result.stats.mrays_per_second:.2f} Mrays/s")
    pipe.scene.camera = start_camera


if __name__ == "__main__":
    main()
