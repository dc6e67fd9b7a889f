"""The robustness conditions a sweep's plans are executed under (`ConditionSpec`), each named:
- `nominal`: the plan's world;
- `mismatch`: friction `mismatch_mu` (0.55 against the plan's 0.7) and the box mass scaled
  by `mismatch_mass_factor` (+20 %) in the simulated plant only; the controller keeps the
  plan's values;
- `push`: a lateral force `push_force` (0.2 N along +x in W, 40 % of the default box's
  weight) on the box for `SimConfig.push_duration` (0.2 s), starting in the middle of the
  plan's middle segment (a switching finger is off the box there when the segment has one);
- the harder worlds of the closed loop, named by their values: `friction-0.4` and
  `friction-0.3` (`friction_mus`: the simulated friction alone), `mass-x2` (`mass_factors`:
  the simulated box mass over the planned one), `push-3N` and `push-6N` (`push_forces`: N
  along +x in W, timed like `push`).
A sweep in space has the same named worlds but its own harder ones (`SPACE_SPEC`, issue #37's acceptance):
`friction-0.4`, `mass-x1.5` and `push-1N` (a horizontal 1 N along +x in W, timed like `push`); its pushes act on
the cube's centre with f_z 0 (`ConditionSpec.space_world`).
"""

from __future__ import annotations

from dataclasses import dataclass

from trajectotree.config import Config, ConfigError, check_range


@dataclass(frozen=True)
class ConditionSpec:
    """What the named robustness conditions change in the simulated world."""

    mismatch_mu: float = 0.55  # friction coefficient of the simulated plant under `mismatch`
    mismatch_mass_factor: float = 1.2  # 1, simulated box mass / planned box mass under `mismatch`
    push_force: tuple[float, float] = (0.2, 0.0)  # N, (f_x, f_y) in W of the push under `push`
    friction_mus: tuple[float, ...] = (0.4, 0.3)  # friction coefficients of the conditions friction-<mu>
    mass_factors: tuple[float, ...] = (2.0,)  # 1, simulated / planned box mass of the conditions mass-x<factor>
    push_forces: tuple[float, ...] = (3.0, 6.0)  # N, along +x in W, of the conditions push-<force>N

    def __post_init__(self):
        check_range("mismatch_mu", self.mismatch_mu, 0.0, 5.0, low_open=True)
        check_range("mismatch_mass_factor", self.mismatch_mass_factor, 0.0, 100.0, low_open=True)
        for i, f in enumerate(self.push_force):
            check_range(f"push_force[{i}]", f, -100.0, 100.0)
        for i, mu in enumerate(self.friction_mus):
            check_range("friction_mus", mu, 0.0, 5.0, low_open=True, index=(i,))
        for i, factor in enumerate(self.mass_factors):
            check_range("mass_factors", factor, 0.0, 100.0, low_open=True, index=(i,))
        for i, f in enumerate(self.push_forces):
            check_range("push_forces", f, -100.0, 100.0, index=(i,))

    def worlds(self) -> dict[str, tuple[float | None, float | None, tuple[float, float] | None]]:
        """{condition name: (simulated friction, simulated / planned mass, push force (N, N) in W)},
        None where the plan's world holds; in the order the tables list them."""
        worlds = {
            "nominal": (None, None, None),
            "mismatch": (self.mismatch_mu, self.mismatch_mass_factor, None),
            "push": (None, None, tuple(self.push_force)),
        }
        worlds |= {f"friction-{mu:g}": (mu, None, None) for mu in self.friction_mus}
        worlds |= {f"mass-x{factor:g}": (None, factor, None) for factor in self.mass_factors}
        return worlds | {f"push-{f:g}N": (None, None, (f, 0.0)) for f in self.push_forces}

    def space_world(self, condition: str, config: Config, mass_kg: float, plan_duration_s: float, segments: int):
        """The simulated world (execution.world.Conditions) of `condition` for a plan in space of a `mass_kg` cube
        lasting `plan_duration_s` over `segments` segments: a push is horizontal, in the middle of the middle
        segment as the plane's (middle_of_middle), for config.sim.push_duration."""
        from trajectotree.execution.world import Conditions, Push

        mu, mass_factor, push = self.worlds()[check_condition(condition, self)]
        return Conditions(
            mu=mu,
            mass=None if mass_factor is None else mass_factor * mass_kg,
            push=None
            if push is None
            else Push(
                force=(*push, 0.0),
                time_s=middle_of_middle(segments, plan_duration_s),
                duration_s=config.sim.push_duration,
            ),
        )

    def simulation_kwargs(self, condition: str, config: Config, plan_duration_s: float) -> dict:
        """The `run_simulation` keyword arguments (sim_mu, sim_mass, push) of `condition`."""
        from trajectotree.execution.world import Push

        mu, mass_factor, push = self.worlds()[check_condition(condition, self)]
        kwargs = {}
        if mu is not None:
            kwargs["sim_mu"] = mu
        if mass_factor is not None:
            kwargs["sim_mass"] = mass_factor * config.scene.box_mass
        if push is not None:
            kwargs["push"] = Push(
                force=push,
                time_s=middle_of_middle_segment(config, plan_duration_s),
                duration_s=config.sim.push_duration,
            )
        return kwargs


DEFAULT_SPEC = ConditionSpec()  # frozen: a default argument every caller may share
CONDITIONS = tuple(DEFAULT_SPEC.worlds())  # the default spec's condition names
# A sweep in space's: the acceptance worlds (friction 0.4 against the plan's 0.7, a 1 N horizontal push,
# the cube 50 % heavier) beside the shared nominal, mismatch and push.
SPACE_SPEC = ConditionSpec(friction_mus=(0.4,), mass_factors=(1.5,), push_forces=(1.0,))
SPACE_CONDITIONS = tuple(SPACE_SPEC.worlds())


def middle_of_middle_segment(config: Config, plan_duration_s: float) -> float:
    """s, the middle of segment floor((N-1)/2) of a plan with N nodes of equal-length segments
    (a plan's config holds its N; without one, N - 1 is the duration over a segment's)."""
    nodes = config.search.num_nodes
    if nodes is None:
        nodes = round(plan_duration_s / (config.cito.knots_per_segment * config.cito.dt)) + 1
    return middle_of_middle(max(nodes - 1, 1), plan_duration_s)


def middle_of_middle(segments: int, plan_duration_s: float) -> float:
    """s, the middle of segment floor(segments/2) (from 0) of a plan of `segments` equal-length segments."""
    length = plan_duration_s / segments
    return (segments // 2 + 0.5) * length


def check_condition(condition: str, spec: ConditionSpec | None = None) -> str:
    """`condition` if `spec` (default: the default spec) names it; ConfigError naming it otherwise."""
    names = CONDITIONS if spec is None else tuple(spec.worlds())
    if condition not in names:
        raise ConfigError(field="condition", value=condition, problem="is unknown", choices=names)
    return condition
