"""Benchmarks (never timed unit tests): ``python -m benchmarks`` or ``formation-env bench``.

Each module exposes ``TITLE``, ``run(quick: bool) -> list[dict]`` and
``markdown(rows) -> str``; the runner writes BENCHMARKS.md with machine and date.
``python -m benchmarks.ppo_profile`` profiles where PPO's time goes with one env, run on its own.
"""
