"""The README's pictures of the shipped models: one greedy episode of each as a small GIF.

    .venv/bin/python docs/model_gifs.py --out docs/figures [--seed 12345] [--models minatar-breakout,...]

Plays `models/<name>/` on its plain env with `render_mode="rgb_array"` (the episode of
evaluate.py's first seed), keeps every `--every`-th frame at half size (MinAtar's grid, drawn in
its own colours at 48 pixels a cell by `envs/minatar_pixels.py`, at 24), and writes
`<out>/model-<name>.gif` atomically with Pillow (installed with matplotlib).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from PIL import Image

from dqfd_bc_keras import runtime

os.environ.update(runtime.environment())  # runtime.configure()'s settings, before TensorFlow loads

from dqfd_bc_keras.envs.make import make_plain_env
from dqfd_bc_keras.evaluation import load_policy
from dqfd_bc_keras.files import atomic_path

MODELS = Path(__file__).resolve().parents[1] / "models"


def episode_frames(name: str, seed: int) -> tuple[list, float]:
    """The rendered frames of one greedy episode of models/`name`, and its return."""
    policy, settings = load_policy(MODELS / name)
    env = make_plain_env(settings.task, settings.timeout, settings.max_steps, render_mode="rgb_array")
    obs, _ = env.reset(seed=seed)
    frames, total, done = [env.render()], 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        frames.append(env.render())
        total, done = total + float(reward), terminated or truncated
    env.close()
    return frames, total


def picture(frame) -> Image.Image:
    """A rendered frame (RGB uint8) as a GIF frame: half size."""
    return Image.fromarray(frame).reduce(2)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="directory of the GIFs (the README shows docs/figures)")
    parser.add_argument("--seed", type=int, default=12345)
    parser.add_argument("--every", type=int, default=3, help="keep every N-th frame (default 3)")
    parser.add_argument("--models", help="comma-separated folders of models/ (default: all)")
    args = parser.parse_args(argv)
    wanted = None if args.models is None else set(args.models.split(","))
    for folder in sorted(
        p for p in MODELS.iterdir() if (p / "q_network.keras").is_file() and (wanted is None or p.name in wanted)
    ):
        frames, total = episode_frames(folder.name, args.seed)
        images = [picture(f) for f in frames[:: args.every]]
        path = Path(args.out) / f"model-{folder.name}.gif"
        with atomic_path(path, overwrite=True) as tmp:
            images[0].save(
                tmp,
                format="GIF",
                save_all=True,
                append_images=images[1:],
                duration=40 * args.every,
                loop=0,
                optimize=True,
            )
        print(f"{path}: {len(frames) - 1} steps, return {total:g}, {path.stat().st_size / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
