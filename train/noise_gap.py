"""How much a learned policy owes to its action noise.

``python -m train.noise_gap --policy P [--episodes N] [--seed S]`` prints the policy's action noise (the standard
deviation of its Gaussian, per action entry) and its success and collision rates on the suite ``S .. S + N - 1``
acting on its mean action (as every evaluation does) and sampling its Gaussian (as in training; torch seeded with
``S``), with each way's mean time to goal (s). A large gap says the mean action is not a plan: the noise picks what
the mean does not.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import numpy as np

from agents.policy import LearnedPolicy

from .evaluate import evaluate


def noise_gap(policy: str, episodes: int = 100, seed: int = 0) -> dict[str, object]:
    """{"noise": per-entry standard deviation, "deterministic" / "sampled": {success_rate, collision_rate,
    time_to_goal}}."""
    import torch

    pol = LearnedPolicy.load(policy)
    out: dict[str, object] = {"noise": [round(float(v), 3) for v in np.exp(pol.model.policy.log_std.detach().numpy())]}
    for key, det in (("deterministic", True), ("sampled", False)):
        pol.deterministic = det
        torch.manual_seed(seed)
        m = evaluate(pol, None, episodes, seed, generalisation=False)["metrics"]
        out[key] = {k: m[k] for k in ("success_rate", "collision_rate", "time_to_goal")}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m train.noise_gap", description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="a saved SB3 policy (.zip)")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    print(json.dumps(noise_gap(a.policy, a.episodes, a.seed)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
