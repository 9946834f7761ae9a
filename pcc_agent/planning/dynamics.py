"""Latent dynamics as the planner sees them: a step function and its Jacobians.

The planner needs two batched operations on ``N`` state-action pairs (``N`` is any flattened
batch: problems x time steps, or problems x line-search step sizes):

* ``step(z, u) -> z_next`` with ``z`` ``(N, nz)``, ``u`` ``(N, nu)``, ``z_next`` ``(N, nz)``;
* ``jacobians(z, u) -> (A, B)`` with ``A = d z_next / d z`` ``(N, nz, nz)`` and
  ``B = d z_next / d u`` ``(N, nz, nu)``.

A dynamics object may also carry ``packed_mlp`` (a
:class:`~pcc_agent.planning.kernels.PackedMLP`, as :class:`MLPDynamics` does): the planner's
sequential rollouts then run as compiled loops on the CPU instead of one torch call per
tiny matrix product (a 200-step plan is 200 dependent steps).

:class:`LatentDynamics` is that protocol. :func:`as_dynamics` wraps whatever is given: an object
that already follows the protocol, a learned model exposing ``transition_mean(z, u)`` and
``linearize(z, u)`` (:class:`ModelDynamics`), or a plain function (:class:`FunctionDynamics`,
Jacobians by ``torch.func``). :class:`MLPDynamics` is a plain MLP transition with analytic
Jacobians, used by benchmarks and tests.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch
from torch import Tensor

from pcc_agent.planning.kernels import RELU, TANH, PackedMLP, pack_mlp


@runtime_checkable
class LatentDynamics(Protocol):
    """Deterministic latent transition ``z_next = f(z, u)`` with batched Jacobians."""

    def step(self, z: Tensor, u: Tensor) -> Tensor:
        """Next states ``(N, nz)`` from states ``(N, nz)`` and actions ``(N, nu)``."""
        ...

    def jacobians(self, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Jacobians ``A`` ``(N, nz, nz)`` and ``B`` ``(N, nz, nu)`` of ``step`` at ``(z, u)``."""
        ...


class FunctionDynamics:
    """Dynamics from any differentiable function, Jacobians by ``vmap(jacrev(fn))``.

    Args:
        fn: Function mapping one state ``(nz,)`` and one action ``(nu,)`` to the next state
            ``(nz,)``, written with torch operations; it is also called on batches
            ``(N, nz), (N, nu)`` by ``step``, so it must broadcast over a leading dimension
            (any function built from ``torch.nn`` layers does).

    Example:
        >>> import torch
        >>> dynamics = FunctionDynamics(lambda z, u: z + 0.1 * torch.tanh(u).sum(-1, keepdim=True))
        >>> A, B = dynamics.jacobians(torch.zeros(4, 2), torch.zeros(4, 1))
        >>> A.shape, B.shape
        (torch.Size([4, 2, 2]), torch.Size([4, 2, 1]))
    """

    def __init__(self, fn: Callable[[Tensor, Tensor], Tensor]) -> None:
        self.fn = fn
        self._jacobian = torch.func.vmap(torch.func.jacrev(fn, argnums=(0, 1)))

    def step(self, z: Tensor, u: Tensor) -> Tensor:
        """Next states ``fn(z, u)`` for a batch."""
        return self.fn(z, u)

    def jacobians(self, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Jacobians of ``fn`` for each pair in the batch."""
        A, B = self._jacobian(z, u)
        return A, B


class ModelDynamics:
    """Adapter for a learned model with ``transition_mean(z, u)`` and ``linearize(z, u)``.

    ``linearize(z, u)`` must return ``(A, B)`` (extra trailing outputs, such as an offset,
    are ignored) for batches ``(N, nz), (N, nu)``. The model is used without gradient
    tracking; put it in evaluation mode before planning.

    Args:
        model: The learned latent model (for instance ``pcc_agent.model.EmbeddingModel``).
    """

    def __init__(self, model: Any) -> None:
        self.model = model

    def step(self, z: Tensor, u: Tensor) -> Tensor:
        """Mean of the learned transition."""
        return self.model.transition_mean(z, u)

    def jacobians(self, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Jacobians from the model's own ``linearize``."""
        out = self.model.linearize(z, u)
        return out[0], out[1]


def as_dynamics(obj: Any) -> LatentDynamics:
    """Wrap ``obj`` so that it follows :class:`LatentDynamics`.

    Args:
        obj: An object with ``step`` and ``jacobians``; or one with ``transition_mean`` and
            ``linearize`` (a learned model); or a callable ``fn(z, u) -> z_next``.

    Returns:
        A dynamics object for the planner.

    Raises:
        TypeError: If ``obj`` is none of these.
    """
    if hasattr(obj, "step") and hasattr(obj, "jacobians"):
        return obj
    if hasattr(obj, "transition_mean") and hasattr(obj, "linearize"):
        return ModelDynamics(obj)
    if callable(obj):
        return FunctionDynamics(obj)
    raise TypeError(
        f"Cannot plan with a {type(obj).__name__}: pass an object with step(z, u) and "
        "jacobians(z, u), a model with transition_mean(z, u) and linearize(z, u), or a "
        "function fn(z, u) -> z_next."
    )


_ACTIVATIONS: dict[str, tuple[Callable[[Tensor], Tensor], Callable[[Tensor, Tensor], Tensor]]] = {
    # name: (activation, derivative as a function of (pre-activation, activation))
    "relu": (torch.relu, lambda a, h: (a > 0).to(a.dtype)),
    "tanh": (torch.tanh, lambda a, h: 1.0 - h * h),
}


class MLPDynamics:
    """Plain MLP transition ``z_next = [z +] W_L s(... s(W_1 [z; u] + b_1) ...) + b_L``.

    Jacobians are analytic (a product of weight matrices and activation derivatives), much
    cheaper than ``torch.func`` for the planner's many small batches. The first layer is kept
    split into its ``z`` and ``u`` columns so that no concatenation is needed.

    Args:
        weights: Weight matrices ``(out, in)`` of the layers; the first takes ``nz + nu`` inputs
            (state first) and the last outputs ``nz``.
        biases: Bias vectors, one per layer.
        activation: ``"relu"`` or ``"tanh"``, applied after every layer but the last.
        residual: Whether the network predicts the change ``z_next - z``.
    """

    def __init__(
        self,
        weights: Sequence[Tensor],
        biases: Sequence[Tensor],
        activation: str = "relu",
        residual: bool = False,
    ) -> None:
        if activation not in _ACTIVATIONS:
            raise ValueError(
                f"activation must be one of {sorted(_ACTIVATIONS)}, got {activation!r}."
            )
        if len(weights) != len(biases) or len(weights) < 1:
            raise ValueError("Pass one bias per weight matrix, and at least one layer.")
        self.state_dim = weights[-1].shape[0]
        self.action_dim = weights[0].shape[1] - self.state_dim
        if self.action_dim < 1:
            raise ValueError(
                f"The first layer has {weights[0].shape[1]} inputs, which leaves no action "
                f"input for a {self.state_dim}-d state."
            )
        self.weights = [w.detach() for w in weights]
        self.biases = [b.detach() for b in biases]
        self._w_z = self.weights[0][:, : self.state_dim].T.contiguous()
        self._w_u = self.weights[0][:, self.state_dim :].T.contiguous()
        self._w_t = [w.T.contiguous() for w in self.weights[1:]]
        self.activation = activation
        self.residual = residual
        self._packed: PackedMLP | None = None

    @property
    def packed_mlp(self) -> PackedMLP:
        """Float64 copy for the planner's compiled CPU loops (built on first use)."""
        if self._packed is None:
            def to_numpy(t: Tensor) -> np.ndarray:
                return t.detach().to(device="cpu", dtype=torch.float64).numpy()

            self._packed = pack_mlp([to_numpy(w) for w in self.weights],
                                    [to_numpy(b) for b in self.biases],
                                    RELU if self.activation == "relu" else TANH, self.residual)
        return self._packed

    @classmethod
    def random(
        cls,
        state_dim: int,
        action_dim: int,
        hidden: Sequence[int],
        generator: torch.Generator,
        activation: str = "relu",
        residual: bool = False,
        dtype: torch.dtype = torch.float32,
    ) -> MLPDynamics:
        """A randomly initialized MLP (PyTorch's default uniform fan-in scaling).

        Args:
            state_dim: Latent dimension ``nz``.
            action_dim: Action dimension ``nu``.
            hidden: Hidden layer widths, e.g. ``(20, 20)``.
            generator: Source of randomness.
            activation: ``"relu"`` or ``"tanh"``.
            residual: Whether the network predicts the change of state.
            dtype: Parameter dtype.

        Returns:
            The dynamics.
        """
        sizes = [state_dim + action_dim, *hidden, state_dim]
        weights, biases = [], []
        for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
            bound = fan_in**-0.5
            w = (torch.rand(fan_out, fan_in, generator=generator, dtype=dtype) * 2 - 1) * bound
            b = (torch.rand(fan_out, generator=generator, dtype=dtype) * 2 - 1) * bound
            weights.append(w)
            biases.append(b)
        return cls(weights, biases, activation=activation, residual=residual)

    def step(self, z: Tensor, u: Tensor) -> Tensor:
        """Next states ``(N, nz)``."""
        act = _ACTIVATIONS[self.activation][0]
        x = torch.addmm(self.biases[0], z, self._w_z).addmm_(u, self._w_u)
        for w_t, b in zip(self._w_t, self.biases[1:]):
            x = torch.addmm(b, act(x), w_t)
        return x + z if self.residual else x

    def jacobians(self, z: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """Analytic Jacobians ``A`` ``(N, nz, nz)`` and ``B`` ``(N, nz, nu)``."""
        act, d_act = _ACTIVATIONS[self.activation]
        a = torch.addmm(self.biases[0], z, self._w_z).addmm_(u, self._w_u)
        J = self.weights[0].expand(z.shape[0], -1, -1)
        for w, b, w_t in zip(self.weights[1:], self.biases[1:], self._w_t):
            h = act(a)
            J = w @ (d_act(a, h).unsqueeze(-1) * J)
            a = torch.addmm(b, h, w_t)
        A, B = J[..., : self.state_dim], J[..., self.state_dim :]
        if self.residual:
            A = A + torch.eye(self.state_dim, dtype=A.dtype, device=A.device)
        return A, B

    def __call__(self, z: Tensor, u: Tensor) -> Tensor:
        """Same as :meth:`step`."""
        return self.step(z, u)
