"""One policy interface for analytic planners and learned (SB3) policies.

Every policy offers

* ``act(observation)``: commander observations (B, obs_dim) float32 -> actions (B, act_dim) in [-1, 1]
  (act_dim = n_l p, leaders in order). The commander observation is the engine's global state
  (``Engine.global_state``, shape (B, state_dim)); see :mod:`train.commander`.
* ``act_engine(engine, state, obs=None)``: actions (B, n_l, p) for a batched engine state, used by the
  evaluation harness (it runs the pure engine batched).
* ``act_parallel(obs_dict, env)``: a PettingZoo ``formation_v0`` parallel env's observation dict ->
  actions dict (what ``formation-env rollout`` calls).

Learned policies come from SB3 (:class:`LearnedPolicy`, a ``.zip`` with its statistics and config) or from RLlib
(:class:`RLlibPolicy`, a checkpoint folder written by ``python -m train.rllib``).

Analytic planners need the engine state: ``act`` decodes it from the global state (positions,
velocities, goals, time and scenario parameters are all in it), ``act_parallel`` reads
``env.unwrapped.engine`` and ``env.unwrapped.engine_state``; the interface is identical.

:func:`load_policy` resolves a policy spec (``"analytic"``, ``"random"``, a saved model) once: the policy it returns
knows its scenario and env arguments (``policy.scenario``, ``policy.env_kwargs``: a saved policy's training scenario
and :data:`POLICY_ENV_KWARGS`) and acts in ``policy.engine``.
"""

from __future__ import annotations

import json
import logging
import pickle
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from formation_env.env.engine import Engine, EngineState
from formation_env.env.maneuver import Pose, PoseCommand

from .planner import make_planner

__all__ = [
    "DEFAULT_SCENARIO",
    "POLICY_DIR",
    "POLICY_ENV_KWARGS",
    "SB3_ZIP_ENTRIES",
    "AnalyticPolicy",
    "LearnedPolicy",
    "Policy",
    "RLlibPolicy",
    "RandomPolicy",
    "check_sb3_zip",
    "load_policy",
    "policy_env_kwargs",
    "saved_config",
]

Array = NDArray[np.float64]

#: The shipped policies' folder (``agents/pretrained/``).
POLICY_DIR = Path(__file__).resolve().parent / "pretrained"
#: The scenario of a policy with none of its own (the analytic and random ones, a saved one without a config).
DEFAULT_SCENARIO = "narrow_passage"
#: Engine arguments that set what a saved policy observes and commands: the agents (framework, stress, dynamics,
#: follower law, sampling), the obstacles' count and the sensing. It acts with its training values of these; its other
#: training arguments (reward weights, the scenario's draw ranges and tolerances, the agents' radius) are training
#: choices, and it is evaluated on the scenario's own.
POLICY_ENV_KWARGS: tuple[str, ...] = (
    "dynamics", "follower_law", "dt", "framework", "omega", "law_params", "u_max", "max_speed", "n_obstacles",
    "n_moving", "observation", "state_blocks", "k_nearest", "sense_radius", "obs_noise", "n_rays", "n_nearest",
    "sensor_range",
)  # fmt: skip


def policy_env_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """The :data:`POLICY_ENV_KWARGS` of a saved policy's training ``config`` (its ``env_kwargs``; none without)."""
    return {k: v for k, v in (config.get("env_kwargs") or {}).items() if k in POLICY_ENV_KWARGS}


def _engine_of(env: Any) -> Engine:
    if isinstance(env, Engine):
        return env
    base = getattr(env, "unwrapped", env)
    eng = getattr(base, "engine", None)
    if not isinstance(eng, Engine):
        raise TypeError(f"expected an Engine or an env with an .engine (formation_v0), got {type(env).__name__}")
    return eng


#: The entries of an SB3 save (``model.save``) that loading needs: the model's class, spaces and hyperparameters
#: (``data``, JSON) and the policy network's weights (``policy.pth``).
SB3_ZIP_ENTRIES: dict[str, str] = {
    "data": "the model's class, spaces and hyperparameters",
    "policy.pth": "the policy network's weights",
}


def check_sb3_zip(path: Path) -> None:
    """Refuse a file that is not a saved SB3 model, naming what it misses (instead of SB3's bare assertion).

    Raises:
        ValueError: ``path`` is not a zip archive, or lacks an entry of :data:`SB3_ZIP_ENTRIES`.
    """
    import zipfile

    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a saved SB3 model: not a zip archive (model.save() writes one)")
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
    missing = [f"{name!r} ({what})" for name, what in SB3_ZIP_ENTRIES.items() if name not in names]
    if missing:
        held = ", ".join(sorted(names)[:8]) + (", ..." if len(names) > 8 else "") if names else "nothing"
        raise ValueError(
            f"{path} holds no SB3 model: it lacks {' and '.join(missing)}; it holds {held} (model.save() writes both)"
        )


class Policy:
    """Base class: subclasses implement :meth:`act_engine`; ``act`` and ``act_parallel`` follow from it."""

    name: str = "policy"
    engine: Engine
    #: The engine arguments over the scenario's defaults it was made for (:func:`load_policy` sets them).
    env_kwargs: dict[str, Any] = {}  # replaced per instance, never mutated

    @property
    def scenario(self) -> str:
        """The name of the scenario it acts in (its engine's)."""
        return self.engine.scenario_name

    def act_engine(self, engine: Engine, state: EngineState, obs: Any = None) -> Array:
        """Actions (B, n_l, p) in [-1, 1] for the batched ``state``."""
        raise NotImplementedError

    def act(self, observation: NDArray[np.floating]) -> NDArray[np.float32]:
        """Commander observations (B, state_dim) -> actions (B, n_l p) in [-1, 1], float32."""
        raise NotImplementedError

    def act_parallel(self, obs_dict: dict[str, Any], env: Any) -> dict[str, NDArray[np.float32]]:
        """Per-leader actions of a ``formation_v0`` parallel env: {agent: (p,) float32}."""
        base = getattr(env, "unwrapped", env)
        state = base.engine_state
        if state is None:
            raise RuntimeError("act_parallel needs an env that has been reset")
        a = self.act_engine(base.engine, state, obs_dict).astype(np.float32)[0]
        return {agent: a[i] for i, agent in enumerate(base.possible_agents) if agent in obs_dict}


def decode_state(engine: Engine, gs: NDArray[np.floating]) -> EngineState:
    """An :class:`EngineState` good enough for the planners from global states (B, state_dim).

    Decodes positions, velocities, goals, time, the scenario's parameters (``Scenario.decode_params``) and the
    moving obstacles (``Obstacle.decode``). Values were clipped to the state bounds, so positions outside the
    world box are not exact (they are collisions anyway).
    """
    g = np.asarray(gs, dtype=np.float64)
    B, n, d = g.shape[0], engine.n, engine.d
    sizes = [n * d] * 4 + [1, d * d, int(engine.scenario.param_low.size)]
    probe = engine.reset(np.random.default_rng(0), 1).params
    sizes += [int(ob.state_bounds(probe[ob.key].shape[1], d, engine.bounds)[0].size) for ob in engine.obstacles]
    parts = np.split(g, np.cumsum(sizes + [1]), axis=1)  # ..., time fraction, the state blocks (unused here)
    pos, vel, goal, goal_vel = (a.reshape(B, n, d) for a in parts[:4])
    err, pv, tfrac = parts[4][:, 0], parts[6], parts[len(sizes)][:, 0]
    k = np.rint(tfrac * engine.max_cycles).astype(np.int64)
    th, b = engine.affine.fit(goal)  # static goals: the least-squares fit of the goal positions
    params: dict[str, Array] = {"goal_theta": th, "goal_b": b, **engine.scenario.decode_params(pv)}
    for ob, vec in zip(engine.obstacles, parts[7 : len(sizes)], strict=True):
        dec = ob.decode(vec, engine.dt * k.astype(np.float64), d)
        if dec is not None:
            params[ob.key] = dec
    x = engine.dynamics.state_from_position(pos)
    if engine.kind == "double_integrator":
        x = np.concatenate([pos, vel], axis=-1).reshape(B, n, -1)
    gd = np.linalg.norm(goal - pos, axis=-1)[:, engine.leaders]
    return EngineState(x, pos, vel, None, k, goal, goal_vel, gd, err, k * 0, params)


class AnalyticPolicy(Policy):
    """The scenario's analytic planner (:mod:`agents.planner`) behind the policy interface.

    Args:
        engine: the engine (or a formation_v0 env) it acts in.
        **params: planner parameters (defaults: the tuned ones).
    """

    def __init__(self, engine: Engine | Any, **params: Any) -> None:
        self.engine = _engine_of(engine)
        self.planner = make_planner(self.engine.scenario, **params)
        self.name = "analytic"

    def act_engine(self, engine: Engine, state: EngineState, obs: Any = None) -> Array:
        return self.planner(engine, state)

    def act(self, observation: NDArray[np.floating]) -> NDArray[np.float32]:
        obs = np.atleast_2d(np.asarray(observation))
        state = decode_state(self.engine, obs)
        a = self.planner(self.engine, state)
        return a.reshape(a.shape[0], -1).astype(np.float32)


class RandomPolicy(Policy):
    """Uniform random actions in [-1, 1] from its own generator (seeded: the same seed, the same actions).

    The floor every learned policy must beat. Args: engine (or a formation_v0 env), seed.
    """

    def __init__(self, engine: Engine | Any, seed: int = 0) -> None:
        self.engine = _engine_of(engine)
        self.rng = np.random.default_rng(seed)
        self.name = "random"

    def act_engine(self, engine: Engine, state: EngineState, obs: Any = None) -> Array:
        return self.rng.uniform(-1.0, 1.0, (state.batch_size, engine.n_l, engine.p))

    def act(self, observation: NDArray[np.floating]) -> NDArray[np.float32]:
        B = np.atleast_2d(np.asarray(observation)).shape[0]
        return self.rng.uniform(-1.0, 1.0, (B, self.engine.n_l * self.engine.p)).astype(np.float32)


class TrainedPolicy(Policy):
    """A policy saved with its training config (``config``: scenario, env arguments, ...): it acts in the engine
    given, or in one built from that config."""

    config: dict[str, Any]
    _engine: Engine | None

    @property
    def engine(self) -> Engine:  # type: ignore[override]
        """The engine it acts in (built from the config's scenario and :data:`POLICY_ENV_KWARGS` when not given)."""
        if self._engine is None:
            self.env_kwargs = policy_env_kwargs(self.config)
            self._engine = Engine(str(self.config.get("scenario", DEFAULT_SCENARIO)), **self.env_kwargs)
        return self._engine


class LearnedPolicy(TrainedPolicy):
    """A saved SB3 model with its VecNormalize statistics and config (``<stem>.zip``,
    ``<stem>_vecnormalize.pkl``, ``<stem>_config.json`` side by side).

    ``config["mode"]``: ``"commander"`` (observation = global state, action = all leaders, (n_l p,))
    or ``"shared"`` (one policy per leader on its own observation, action (p,)). A commander trained with
    ``config["action_mode"] = "maneuver"`` commands pose rates (:mod:`formation_env.env.maneuver`): the
    commanded poses are its memory, started afresh for every episode at its first sample (k = 0), with the
    rates of ``config["env_kwargs"]["maneuver_kwargs"]`` (the training's; the defaults when absent).
    """

    def __init__(self, model: Any, vecnorm: Any | None, config: dict[str, Any], engine: Engine | None = None) -> None:
        self.model = model
        self.vecnorm = vecnorm
        self.config = config
        self.mode = str(config.get("mode", "commander"))
        self.residual = float(config.get("residual", 0.0))
        self._planner: Any = None
        self.name = str(config.get("name", f"{config.get('algo', 'learned')}_{self.mode}"))
        self._engine = engine
        self.maneuver = config.get("action_mode", "leaders") == "maneuver"
        #: Act on the mean action (every evaluation); False samples the policy's Gaussian, as in training.
        self.deterministic = True
        self._command: PoseCommand | None = None
        self._pose: Pose | None = None

    @staticmethod
    def paths(path: str | Path) -> tuple[Path, Path, Path]:
        """(model zip, VecNormalize pickle, config json) for a model path with or without ``.zip``."""
        p = Path(path)
        stem = p.with_suffix("") if p.suffix == ".zip" else p
        return stem.with_suffix(".zip"), Path(f"{stem}_vecnormalize.pkl"), Path(f"{stem}_config.json")

    @classmethod
    def load(cls, path: str | Path, engine: Engine | Any | None = None) -> LearnedPolicy:
        """Load the model at ``path`` (.zip) and the statistics and config beside it."""
        from stable_baselines3 import PPO, SAC
        from stable_baselines3.common.utils import ConstantSchedule

        zp, vp, cp = cls.paths(path)
        if not zp.exists():
            raise FileNotFoundError(f"no saved model at {zp}")
        check_sb3_zip(zp)
        config = json.loads(cp.read_text()) if cp.exists() else {}
        algos: dict[str, Any] = {"ppo": PPO, "sac": SAC}
        algo = algos[str(config.get("algo", "ppo"))]
        # Acting needs no training schedule: they are not unpickled, whatever the trainer made them of (RL Zoo's way).
        zero = ConstantSchedule(0.0)
        model = algo.load(str(zp), device="cpu", custom_objects={"learning_rate": 0.0, "lr_schedule": zero,
                                                                 "clip_range": zero})  # fmt: skip
        vecnorm = None
        if vp.exists():
            with open(vp, "rb") as fh:
                vecnorm = pickle.load(fh)
        eng = None if engine is None else _engine_of(engine)
        return cls(model, vecnorm, config, eng)

    def _norm(self, obs: NDArray[np.floating]) -> NDArray[np.float32]:
        o = np.asarray(obs, dtype=np.float32)
        want = self.model.observation_space.shape
        if tuple(want) != o.shape[-1:]:
            where = f"the {self._engine.scenario_name!r} engine" if self._engine is not None else "the env"
            raise ValueError(
                f"the policy takes observations of shape {tuple(want)}, {where} gives {o.shape[-1:]}: evaluate it on "
                f"its training scenario ({self.config.get('scenario', 'see its config.json')!r}) and arguments"
            )
        if self.vecnorm is not None and getattr(self.vecnorm, "norm_obs", False):
            o = np.asarray(self.vecnorm.normalize_obs(o), dtype=np.float32)
        return o

    def _raw(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        a, _ = self.model.predict(self._norm(obs), deterministic=self.deterministic)
        return np.clip(np.asarray(a, dtype=np.float32).reshape(obs.shape[0], -1), -1.0, 1.0)

    def _plan(self, engine: Engine, state: EngineState) -> Array:
        if self._planner is None:
            self._planner = make_planner(engine.scenario)
        return self._planner(engine, state).reshape(state.batch_size, -1)

    def act(self, observation: NDArray[np.floating]) -> NDArray[np.float32]:
        obs = np.atleast_2d(np.asarray(observation, dtype=np.float32))
        if self.config.get("central_critic"):  # the actor reads the leader's own part; the critic's is unused
            obs = np.concatenate([obs, np.zeros((obs.shape[0], self.engine.state_dim), np.float32)], axis=1)
        a = self._raw(obs)
        if self.residual > 0:  # correction of the planner, which reads the state decoded from the observation
            eng = self.engine
            a = np.clip(self._plan(eng, decode_state(eng, obs)) + self.residual * a, -1.0, 1.0).astype(np.float32)
        return a

    def _maneuver(self, engine: Engine, state: EngineState) -> Array:
        """Leader actions (B, n_l, p) of a pose-rate commander: its poses advance by its action on the global
        state and the commanded pose; episodes at k = 0 start a fresh pose."""
        if self._command is None or self._command.engine is not engine:
            rates = self.config.get("env_kwargs", {}).get("maneuver_kwargs", {})  # the training's pose rates
            self._command, self._pose = PoseCommand(engine, **rates), None
        fresh = np.flatnonzero(state.k == 0)
        if self._pose is None or self._pose.b.shape[0] != state.batch_size:
            self._pose = self._command.reset(state)
        elif fresh.size:
            self._pose = self._pose.replace_rows(fresh, self._command.reset(Engine.select(state, fresh)))
        obs = np.concatenate([engine.global_state(state), self._command.observe(self._pose)], axis=1)
        self._pose, a = self._command.step(state, self._pose, self._raw(obs.astype(np.float32)).astype(np.float64))
        return a

    def act_engine(self, engine: Engine, state: EngineState, obs: Any = None) -> Array:
        B = state.batch_size
        if self.mode == "commander" and self.maneuver:
            return self._maneuver(engine, state)
        if self.mode == "commander":
            a64 = self._raw(engine.global_state(state)).astype(np.float64)
            if self.residual > 0:
                a64 = np.clip(self._plan(engine, state) + self.residual * a64, -1.0, 1.0)
            return a64.reshape(B, engine.n_l, engine.p)
        o = engine.observe(state) if not isinstance(obs, np.ndarray) else obs  # (B, n_l, obs_dim)
        a = self.act(o.reshape(B * engine.n_l, -1))
        return a.reshape(B, engine.n_l, engine.p).astype(np.float64)


class RLlibPolicy(TrainedPolicy):
    """The shared leader policy of an RLlib checkpoint (``python -m train.rllib``; extra ``rllib``).

    Every leader acts on its own observation (``Engine.observe``, (obs_dim,)) with one RLModule; the action is
    the mean of its action distribution (deterministic), clipped to [-1, 1]. Only the module is loaded (no
    Ray cluster, no algorithm): env-to-module connectors beyond RLlib's defaults (e.g. an observation filter) are
    not applied, and ``train.rllib`` configures none.

    Args:
        module: the RLModule (``ray.rllib.core.rl_module.RLModule``) of the shared policy.
        config: the run's ``config.json`` (scenario, env_kwargs, env_version, ...; ``{}`` when absent).
        engine: the engine it acts in (built from the config's scenario and env arguments when not given).
        name: its name in tables and file names.
    """

    #: The module id ``train.rllib`` gives the shared policy.
    MODULE_ID = "shared"

    def __init__(self, module: Any, config: dict[str, Any], engine: Engine | None = None, name: str = "rllib") -> None:
        self.module = module
        self.config = config
        self.name = name
        self._engine = engine

    @staticmethod
    def checkpoint_of(path: str | Path) -> Path | None:
        """The RLlib checkpoint folder at ``path``: ``path`` itself (it holds ``rllib_checkpoint.json``) or the
        ``checkpoint/`` inside a ``train.rllib`` output folder; None when ``path`` is neither."""
        p = Path(path)
        for cand in (p, p / "checkpoint"):
            if (cand / "rllib_checkpoint.json").is_file():
                return cand
        return None

    @classmethod
    def config_of(cls, path: str | Path) -> dict[str, Any]:
        """The ``config.json`` that ``train.rllib`` writes beside the checkpoint (``{}`` when there is none)."""
        ckpt = cls.checkpoint_of(path)
        if ckpt is None:
            return {}
        cp = ckpt.parent / "config.json"
        return json.loads(cp.read_text()) if cp.is_file() else {}

    @classmethod
    def load(cls, path: str | Path, engine: Engine | Any | None = None, module_id: str | None = None) -> RLlibPolicy:
        """Load the RLModule ``module_id`` (default: the only one, or ``"shared"``) of the checkpoint at ``path``
        (a checkpoint folder or a ``train.rllib`` output folder)."""
        ckpt = cls.checkpoint_of(path)
        if ckpt is None:
            raise FileNotFoundError(f"no RLlib checkpoint at {path} (no rllib_checkpoint.json in it or in checkpoint/)")
        from formation_env._extras import require

        rl_module = require("ray.rllib.core.rl_module.rl_module", "rllib", "an RLlib checkpoint policy")
        modules = ckpt / "learner_group" / "learner" / "rl_module"
        ids = sorted(d.name for d in modules.iterdir() if d.is_dir()) if modules.is_dir() else []
        if module_id is None:
            module_id = ids[0] if len(ids) == 1 else cls.MODULE_ID
        if module_id not in ids:
            raise ValueError(f"RLlib checkpoint {ckpt} has no module {module_id!r}; its modules: {ids}")
        quiet = logging.getLogger("ray._common.deprecation")  # RLlib loading its own checkpoint warns of itself
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            module = rl_module.RLModule.from_checkpoint(str(modules / module_id))
        finally:
            quiet.setLevel(level)
        eng = None if engine is None else _engine_of(engine)
        return cls(module, cls.config_of(ckpt), eng, name=f"rllib_{module_id}")

    def act(self, observation: NDArray[np.floating]) -> NDArray[np.float32]:
        """Per-leader observations (N, obs_dim) -> actions (N, p) in [-1, 1], float32 (deterministic)."""
        import torch

        obs = torch.as_tensor(np.atleast_2d(np.asarray(observation, dtype=np.float32)))
        with torch.no_grad():
            out = self.module.forward_inference({"obs": obs})
            dist = self.module.get_inference_action_dist_cls().from_logits(out["action_dist_inputs"])
            a = dist.to_deterministic().sample().cpu().numpy()
        return np.clip(np.asarray(a, dtype=np.float32).reshape(obs.shape[0], -1), -1.0, 1.0)

    def act_engine(self, engine: Engine, state: EngineState, obs: Any = None) -> Array:
        B = state.batch_size
        o = engine.observe(state) if not isinstance(obs, np.ndarray) else obs  # (B, n_l, obs_dim)
        want = getattr(getattr(self.module, "observation_space", None), "shape", None)
        if want is not None and tuple(want) != (o.shape[-1],):
            raise ValueError(
                f"the RLlib policy takes observations of shape {tuple(want)}, the {engine.scenario_name!r} engine "
                f"gives ({o.shape[-1]},): evaluate it on its training scenario "
                f"({self.config.get('scenario', 'see its config.json')!r}) and arguments"
            )
        a = self.act(o.reshape(B * engine.n_l, -1))
        return a.reshape(B, engine.n_l, engine.p).astype(np.float64)


def saved_config(spec: str | Path) -> dict[str, Any]:
    """The training config of a saved policy spec (an SB3 model's ``<stem>_config.json``, an RLlib run's
    ``config.json``; ``{}`` for ``"analytic"``, ``"random"`` and a saved policy without one)."""
    if str(spec) in ("analytic", "random"):
        return {}
    if RLlibPolicy.checkpoint_of(spec) is not None:
        return RLlibPolicy.config_of(spec)
    cp = LearnedPolicy.paths(spec)[2]
    return dict(json.loads(cp.read_text())) if cp.is_file() else {}


def load_policy(
    spec: str | Path | Policy,
    env: Engine | Any | None = None,
    *,
    scenario: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> Policy:
    """The policy of ``spec``, knowing its scenario and env arguments: ``"analytic"`` -> :class:`AnalyticPolicy`;
    ``"random"`` -> :class:`RandomPolicy` (seed 0); an RLlib checkpoint folder (or a ``train.rllib`` output folder)
    -> :class:`RLlibPolicy`; another path -> :class:`LearnedPolicy` (``.zip``, or its stem); a Policy is returned as
    is.

    Args:
        env: an :class:`Engine` or a formation_v0 env it acts in; None: an engine is built from ``scenario`` and
            ``env_kwargs``.
        scenario: default: a saved policy's training scenario, else :data:`DEFAULT_SCENARIO`.
        env_kwargs: engine arguments; default: a saved policy's training values of :data:`POLICY_ENV_KWARGS`, else
            none.
    Returns:
        The policy; ``policy.engine`` is the engine it acts in, ``policy.scenario`` its scenario and
        ``policy.env_kwargs`` the arguments that engine was built with (``{}`` when ``env`` was given).
    Raises:
        ValueError: ``env`` given with ``scenario`` or ``env_kwargs``.
    """
    if isinstance(spec, Policy):
        return spec
    if env is not None and (scenario is not None or env_kwargs is not None):
        raise ValueError("load_policy takes an env to act in, or scenario and env_kwargs to build one, not both")
    kw: dict[str, Any] = {}
    if env is None:
        config = saved_config(spec)
        kw = dict(env_kwargs) if env_kwargs is not None else policy_env_kwargs(config)
        env = Engine(scenario if scenario is not None else str(config.get("scenario", DEFAULT_SCENARIO)), **kw)
    policy: Policy
    if str(spec) == "analytic":
        policy = AnalyticPolicy(env)
    elif str(spec) == "random":
        policy = RandomPolicy(env)
    elif RLlibPolicy.checkpoint_of(spec) is not None:
        policy = RLlibPolicy.load(spec, env)
    elif Path(spec).is_dir():
        raise FileNotFoundError(f"{spec} is a folder but not an RLlib checkpoint (no rllib_checkpoint.json)")
    else:
        policy = LearnedPolicy.load(spec, env)
    policy.env_kwargs = kw
    return policy
