"""`python -m dqfd_bc_keras.demos.experts`: the scripted experts' returns on their plain envs, as a table."""

from __future__ import annotations

from collections.abc import Sequence

from dqfd_bc_keras.commands.cli import ArgumentParser, positive_int, run
from dqfd_bc_keras.demos.recording import expert_returns
from dqfd_bc_keras.tasks import families, family_preset


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m dqfd_bc_keras.demos.experts", description="Evaluate the scripted experts on the plain envs."
    )
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--epsilon", type=float, default=0.0)
    args = parser.parse_args(argv)
    print("| family | expert | env id | episodes | mean ± std | min | max |")
    print("|---|---|---|---|---|---|---|")
    for family in families():
        preset = family_preset(family)
        for name in preset.experts:
            r = expert_returns(family, name, args.episodes, args.seed, args.epsilon)
            print(
                f"| {family} | {name} | {preset.env_id} | {args.episodes} "
                f"| {r.mean():.2f} ± {r.std():.2f} | {r.min():g} | {r.max():g} |"  # MiniGrid's are fractions
            )
    return 0


def cli() -> int:
    return run(main)
