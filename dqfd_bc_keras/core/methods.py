"""The registry of methods: what `expert_loss` may name, and everything that follows from it.

A method declares its name, whether it learns from demonstrations, how its BC model π_bc is
fitted (none, MLE or MAP with dropout, ALGORITHM.md §3), its expert-loss term J_E (§2), the eager
formula J_E is checked against (reference.py) and the Config fields only it reads. Validation, the
agent, the BC builder, the reference and the lab's pairing rules all read these declarations, so a
new method is one `Method(...)`, its term and its reference (each a `Term`):

    from dqfd_bc_keras.core.methods import Method, register

    def j_e(agent, q, batch):                      # J_E, a scalar tensor (see expert_terms.py)
        return ...

    def j_e_by_hand(agent, q, batch):              # the same J_E, written independently of `j_e`
        return ...

    SOFT_MARGIN = register(Method("soft_margin", "a softer margin", bc_fit="mle", term=j_e, reference=j_e_by_hand))

and `train.py --expert-loss my_module:SOFT_MARGIN` trains with it (the module is imported, and
the `Method` it names is registered under its own name; config.json records `my_module:SOFT_MARGIN`
so `--resume` finds it again; evaluating the run does not need it). This module imports no
TensorFlow: reading a config.json does not load it.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, cast

from dqfd_bc_keras.choices import DYNAMIC_MODES
from dqfd_bc_keras.core.search_space import Choice, Dimension, Span, check_own
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.plugins import PluginError, WrongKind, load, parse

if TYPE_CHECKING:
    import tensorflow as tf

    from dqfd_bc_keras.core.config import Config

BC_FITS = ("none", "mle", "map")
"""How a method fits π_bc: not at all, by maximum likelihood (ce, bc_margin), or MAP with dropout (bayes)."""

BC_FIELDS = ("bc_hidden", "bc_learning_rate", "bc_epochs")
"""Config fields every method with a BC model reads."""
DYNAMIC_FIELDS = ("dynamic_demos", "dynamic_window", "dynamic_rollouts", "bc_refit_epochs")
"""Config fields of the dynamic demonstrations, which grow D_demo for the methods with a BC model (§5)."""
BAYES_FIELDS = (
    "sigma0_sq",
    "mc_passes",
    "prior_scale",
    "prior_center",
    "bc_dropout",
    "bc_prior_scale",
    "bayes_prior",
    "mc_dropout",
    "uncertainty",
    "ensemble_members",
)
"""Config fields of the Bayesian expert loss and its MAP BC model (§3)."""
LOCAL_FIELDS = tuple(f for f in BAYES_FIELDS if f not in ("mc_passes", "mc_dropout", "uncertainty", "ensemble_members"))
"""What `bayes_local` reads of them: its estimator is fixed (`local`), one pass, no MC dropout."""


class TermAgent(Protocol):
    """What a term may read of the agent: all that the built-in terms read. `DQfDAgent` (agent.py)
    gives it in the learning graph, `ReferenceLearner` (reference.py) eagerly."""

    @property
    def config(self) -> Config:
        """The run's Config: the method's settings (margin, temperature, prior_scale, …)."""

    @property
    def theta(self) -> Sequence[tf.Variable | tf.Tensor]:
        """θ, the Q-network's trainable weights (the Bayesian prior's ‖θ − θ_prior‖²)."""

    @property
    def prior_weights(self) -> Sequence[tf.Variable | tf.Tensor]:
        """θ_prior, one tensor per weight of θ: zero while pre-training, then (by default) θ after it."""

    @property
    def demo_size(self) -> int | tf.Tensor | tf.Variable:
        """N = |D_demo|, the demonstrated transitions (the prior's 1/N)."""

    @property
    def expert_scale(self) -> float | tf.Tensor | tf.Variable:
        """w_E, the teacher-relative weight of a method with a `decay` (1 for the others)."""


class TermBatch(Protocol):
    """What a term may read of the batch, each a tensor of B rows: `replay.Batch` has these and
    the transitions themselves."""

    @property
    def actions(self) -> tf.Tensor:
        """(B,) int32 a_t: on D_demo's rows the demonstrated action a_E."""

    @property
    def is_demo(self) -> tf.Tensor:
        """(B,) 1.0 on D_demo's rows, 0.0 on the agent's own."""

    @property
    def weights(self) -> tf.Tensor:
        """(B,) the prioritized replay's importance weights w_i (max 1): weight each row's loss by them."""

    @property
    def pi_bc(self) -> tf.Tensor:
        """(B, A) π̄_bc(·|s_t), the BC model's (mean) policy (uniform for a method without one)."""

    @property
    def sigma_sq(self) -> tf.Tensor:
        """(B,) σ²(s_t), the BC model's predictive variance (σ0² for an MLE model or none)."""


class Term(Protocol):
    """J_E: term(agent, q, batch) → a scalar tensor, `q` = Q(s, ·; θ) of the batch, (B, A). A
    method's term runs inside the learning graph (TensorFlow ops on `q` and the batch; J_E's
    gradient flows through `q` and `agent.theta`); its reference runs eagerly (reference.py)."""

    def __call__(self, agent: TermAgent, q: tf.Tensor, batch: TermBatch, /) -> tf.Tensor: ...


@dataclass(frozen=True)
class Method:
    """One value of `expert_loss`."""

    name: str
    doc: str
    needs_demos: bool = True
    """Whether the method learns from demonstrations (pre-training on D_demo, ε from 0.1)."""
    bc_fit: str = "none"
    """How π_bc is fitted: none | mle | map (BC_FITS)."""
    term: Term | str | None = None
    """J_E: a callable term(agent, q, batch), or "module:function" naming one (imported when the
    agent is built, so declaring a method loads no TensorFlow); None: no expert loss."""
    reference: Term | str | None = None
    """The same J_E as an eager formula written independently of `term` (a `Term` or "module:function"),
    which tests and reference.py check `term` against; reference.py refuses a method with a term
    and no reference. The built-ins' are in reference.py."""
    reads: tuple[str, ...] = ()
    """The Config fields only this method (among the registered ones) reads besides the shared ones."""
    space: tuple[tuple[str, Dimension], ...] = ()
    """Where a hyperparameter search varies the fields it reads (`experiments tune`), as (field,
    `search_space.Span` or `Choice`) pairs; the shared fields' ranges are `search_space.SHARED`."""
    sqil_rewards: bool = False
    """SQIL's relabelling: reward 1 on demonstrations and 0 on the agent's own data, in batches drawn
    half from each replay, uniformly (Reddy et al. 2020)."""
    q_learning: bool = True
    """False for behavioural cloning alone: π_bc is the policy and no Q-network is trained."""
    weight: Term | str | None = None
    """The imitation weight J_E puts on each row, term(agent, q, batch) → (B,) (or "module:function"):
    what a run logs as `imitation_weight_demo` and `imitation_weight_agent`, averaged over D_demo's
    rows and D_replay's. None: J_E weighs every row alike, and nothing is logged."""
    uncertainty: str | None = None
    """The σ² estimator the method always uses (`choices.UNCERTAINTIES`); None: `Config.uncertainty`."""
    decay: float | None = None
    """ρ of a teacher-relative expert weight w_E (`expert_terms.next_expert_scale`): after each
    episode w_E ← ρ·w_E while the agent's last W returns average at least the teacher's, and
    w_E ← min(1, w_E/ρ) while they do not. None: no such weight (w_E = 1)."""

    def __post_init__(self) -> None:
        if self.bc_fit not in BC_FITS:
            raise ConfigError(f"method {self.name!r}: bc_fit={self.bc_fit!r} is not one of {BC_FITS}")
        if self.reference is not None and self.term is None:
            raise ConfigError(f"method {self.name!r}: a reference without a term (J_E = 0) checks nothing")
        if self.decay is not None and not 0.0 < self.decay < 1.0:
            raise ConfigError(f"method {self.name!r}: decay={self.decay!r} must lie in (0, 1)")
        check_own(self.name, self.space, self.reads)

    @property
    def uses_bc(self) -> bool:
        return self.bc_fit != "none"

    def expert_term(self) -> Term | None:
        """The callable J_E (a "module:function" term imported now)."""
        return self._imported(self.term, "term")

    def reference_term(self) -> Term | None:
        """The callable reference formula of J_E (a "module:function" imported now)."""
        return self._imported(self.reference, "reference")

    def weight_term(self) -> Term | None:
        """The callable per-row imitation weight (a "module:function" imported now)."""
        return self._imported(self.weight, "weight")

    def _imported(self, term: Term | str | None, field: str) -> Term | None:
        if not isinstance(term, str):
            return term
        return cast("Term", load(term, f"method {self.name!r}: {field} {term}", callable, "function"))


_BC_SPACE: tuple[tuple[str, Dimension], ...] = (
    ("bc_learning_rate", Span(1e-4, 3e-3, log=True)),
    ("bc_epochs", Span(10, 120, log=True)),
    ("dynamic_demos", Choice(DYNAMIC_MODES)),
)
"""What every method with a BC model varies of it: its fit, and how D_demo grows (§5)."""
_BAYES_SPACE: tuple[tuple[str, Dimension], ...] = (
    ("sigma0_sq", Span(0.05, 5.0, log=True)),
    ("prior_scale", Span(0.1, 10.0, log=True)),
    ("bc_dropout", Span(0.05, 0.5)),
)
"""What the Bayesian methods vary of the likelihood, the prior and the MAP BC model."""
_TERMS = "dqfd_bc_keras.core.expert_terms"
_REFERENCE = "dqfd_bc_keras.core.reference"
_METHOD = "dqfd_bc_keras.core.methods.Method"
METHODS: dict[str, Method] = {
    method.name: method
    for method in (
        Method(
            "margin",
            "DQfD's large-margin loss on the demonstrated actions (§2)",
            term=f"{_TERMS}:margin",
            reference=f"{_REFERENCE}:margin",
            reads=("margin",),
            space=(("margin", Span(0.1, 2.0)),),
        ),
        Method(
            "bc_margin",
            "DQfD-BC: the large margin around the BC model's action argmax π_bc",
            bc_fit="mle",
            term=f"{_TERMS}:bc_margin",
            reference=f"{_REFERENCE}:bc_margin",
            reads=("margin", *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("margin", Span(0.1, 2.0)), *_BC_SPACE),
        ),
        Method(
            "ce",
            "DQfD-BC: the cross-entropy H(π_bc, softmax(Q/T)) on every row",
            bc_fit="mle",
            term=f"{_TERMS}:ce",
            reference=f"{_REFERENCE}:ce",
            reads=("temperature", *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("temperature", Span(0.1, 10.0, log=True)), *_BC_SPACE),
        ),
        Method(
            "bayes",
            "the paper's Bayesian loss: Gaussian likelihood weighted by 1/σ²(s), and a prior around θ_prior",
            bc_fit="map",
            term=f"{_TERMS}:bayes",
            reference=f"{_REFERENCE}:bayes",
            weight=f"{_TERMS}:likelihood_weight",
            reads=("temperature", *BAYES_FIELDS, *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("temperature", Span(0.1, 10.0, log=True)), *_BAYES_SPACE, *_BC_SPACE),
        ),
        # Past the teacher (ALGORITHM.md §8): each lets the agent leave π_bc where its own Q says so.
        Method(
            "qfilter",
            "ce only where Q(s, a_bc) + l ≥ max_a Q(s, a): where the agent does not prefer another action "
            "by the margin (the Q-filter of Nair et al. 2018)",
            bc_fit="mle",
            term=f"{_TERMS}:qfilter",
            reference=f"{_REFERENCE}:qfilter",
            weight=f"{_TERMS}:qfilter_weight",
            reads=("temperature", "margin", *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("temperature", Span(0.1, 10.0, log=True)), ("margin", Span(0.0, 2.0)), *_BC_SPACE),
        ),
        Method(
            "ce_decay",
            "ce weighted by w_E, which decays while the agent's own returns reach the teacher's",
            bc_fit="mle",
            term=f"{_TERMS}:ce_decay",
            reference=f"{_REFERENCE}:ce_decay",
            weight=f"{_TERMS}:decay_weight",
            reads=("temperature", *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("temperature", Span(0.1, 10.0, log=True)), *_BC_SPACE),
            decay=0.9,
        ),
        Method(
            "bayes_local",
            "the Bayesian loss with σ²(s) = σ0²/k(s), k the kernel of the distance to the nearest demonstration",
            bc_fit="map",
            term=f"{_TERMS}:bayes",
            reference=f"{_REFERENCE}:bayes",
            weight=f"{_TERMS}:likelihood_weight",
            reads=("temperature", *LOCAL_FIELDS, *BC_FIELDS, *DYNAMIC_FIELDS),
            space=(("temperature", Span(0.1, 10.0, log=True)), *_BAYES_SPACE, *_BC_SPACE),
            uncertainty="local",
        ),
        Method("none", "plain DQN: no demonstrations, no expert loss", needs_demos=False),
        Method(
            "sqil",
            "SQIL on our DQN: no J_E; rewards 1 on demonstrations, 0 on the agent's, half of each batch from D_demo",
            sqil_rewards=True,
        ),
        Method(
            "bc-alone",
            "behavioural cloning alone: the MLE BC model is the policy; no Q-learning",
            bc_fit="mle",
            reads=BC_FIELDS,
            q_learning=False,
        ),
    )
}
"""Every registered method by name; `get_method` also imports a user's `module:NAME`."""
BUILT_IN = tuple(METHODS)
"""The package's own methods: any other name in METHODS was registered by a user's code."""


def register(method: Method) -> Method:
    """Add `method` to the registry (a user's own, from their module; it replaces one of its name
    registered before); returns it. A built-in's name is refused: a run's config.json records the
    name, and every later reader (evaluate.py, the lab) would take the run for the built-in's."""
    if not isinstance(method, Method):
        raise ConfigError(f"register() takes a Method, got {type(method).__name__}")
    if method.name in BUILT_IN and METHODS[method.name] is not method:
        raise ConfigError(
            f"register(): {method.name!r} is the name of a built-in method ({', '.join(BUILT_IN)}); "
            "give yours a name of its own"
        )
    METHODS[method.name] = method
    return method


_SAVED = ContextVar("reading_saved_config", default=False)


@contextmanager
def reading_saved_config() -> Iterator[None]:
    """While a saved run's config.json is read, a method of the user's own whose module cannot be
    imported here stands in as a plain `Method` (demonstrations, no BC model, no term): evaluating
    a run needs its settings, not its loss. Asking the config for its method afterwards (training,
    `--resume`) imports the module again and reports it missing."""
    token = _SAVED.set(True)
    try:
        yield
    finally:
        _SAVED.reset(token)


_PLAYING = ContextVar("playing_saved_run", default=False)


@contextmanager
def playing_saved_run() -> Iterator[None]:
    """While a saved run is read to be played (evaluate.py), a method of the user's own, `module:NAME`,
    is not imported at all (its module's top-level code does not run): it stands in as a plain
    `Method`. Playing a run needs its network and its env, never its loss."""
    token = _PLAYING.set(True)
    try:
        yield
    finally:
        _PLAYING.reset(token)


def get_method(name: str) -> Method:
    """The method called `name`, or a user's `module:NAME` (a `Method` object in an importable module)."""
    if name in METHODS:
        return METHODS[name]
    if _PLAYING.get() and parse(name) is not None:
        return Method(name, "a method of your own, not imported: a run is played without its loss")
    if parse(name) is None:
        if _SAVED.get():  # a run of a Method a script registered (DQfD(expert_loss=Method(...)))
            return Method(name, "a method a script registered, not registered here")
        raise ConfigError(
            f"expert_loss={name!r} is not one of {tuple(METHODS)} (or a method of your own as "
            "module:NAME, a dqfd_bc_keras.core.methods.Method; one a script registered is registered "
            "again with dqfd_bc_keras.core.methods.register)"
        )
    try:
        return cast(Method, load(name, f"expert_loss={name!r}", lambda value: isinstance(value, Method), _METHOD))
    except PluginError as error:
        if _SAVED.get() and not isinstance(error, WrongKind):
            return Method(name, f"a method of your own that cannot be imported here ({error})")
        raise


def method_fields() -> set[str]:
    """The Config fields some registered method reads and others do not."""
    return {field for method in METHODS.values() for field in method.reads}
