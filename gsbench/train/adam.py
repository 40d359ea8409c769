"""Adam for the harness's optimisers (the Gaussians, the feature autoencoder, grouping's classifier).

Why not `torch.optim.Adam`: its first `step`, `zero_grad` or `state_dict` imports `torch._dynamo`
(about 1.6 s per process, through torch's `_disable_dynamo` wrappers). Every run, and every grid
cell in its own process, paid that; a quick cell trains in less. This is the same update as
torch's Adam without amsgrad, weight decay or maximize, in the order of its single-tensor path,
with the list ("foreach") forms of the same elementwise ops, so each element gets the same
arithmetic: `tests/methods/test_adam.py` compares the parameters bit for bit with
`torch.optim.Adam` over many steps.

The state and `state_dict()` have torch's layout (per parameter `step` as a float32 tensor,
`exp_avg`, `exp_avg_sq`; groups with their options and parameter indices), so checkpoints written
while the harness used `torch.optim.Adam` resume here.
"""
from __future__ import annotations

from typing import Any, Iterable

import torch


class Adam:
    """Adam over parameter groups; each group may set lr, betas and eps and carry other keys
    (e.g. "name"), which are kept. `state` maps a parameter to its step and moments."""

    def __init__(self, params: Iterable[Any], lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.999),
                 eps: float = 1e-8) -> None:
        groups = list(params)
        if not groups:
            raise ValueError("Adam got an empty parameter list")
        if not isinstance(groups[0], dict):
            groups = [{"params": groups}]
        self.defaults = {"lr": float(lr), "betas": (float(betas[0]), float(betas[1])), "eps": float(eps)}
        self.param_groups: list[dict[str, Any]] = [{**self.defaults, **g, "params": list(g["params"])}
                                                   for g in groups]
        self.state: dict[torch.Tensor, dict[str, torch.Tensor]] = {}

    def zero_grad(self, set_to_none: bool = True) -> None:
        for g in self.param_groups:
            for p in g["params"]:
                if set_to_none:
                    p.grad = None
                elif p.grad is not None:
                    p.grad.detach_().zero_()

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient.

        The parameters of all groups that share betas, eps, dtype and device are updated by one call
        of each list op (each group's lr enters through the per-tensor step sizes): the same
        elementwise arithmetic per tensor as one call per group, in a sixth of the calls for the
        Gaussians' six groups."""
        buckets: dict[tuple, list] = {}
        for g in self.param_groups:
            for p in g["params"]:
                if p.grad is None:
                    continue
                if p not in self.state:
                    self.state[p] = {"step": torch.tensor(0.0, dtype=torch.float32),
                                     "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                                     "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format)}
                key = (tuple(g["betas"]), g["eps"], p.dtype, p.device)
                buckets.setdefault(key, []).append((p, g["lr"]))
        for ((beta1, beta2), eps, _, _), members in buckets.items():
            params = [p for p, _ in members]
            states = [self.state[p] for p in params]
            grads = [p.grad for p in params]
            exp_avgs = [s["exp_avg"] for s in states]
            exp_avg_sqs = [s["exp_avg_sq"] for s in states]
            torch._foreach_add_([s["step"] for s in states], 1.0)
            torch._foreach_lerp_(exp_avgs, grads, 1 - beta1)
            torch._foreach_mul_(exp_avg_sqs, beta2)
            torch._foreach_addcmul_(exp_avg_sqs, grads, grads, 1 - beta2)
            steps = [s["step"].item() for s in states]
            # guarded: 1 - beta ** step > 0 for 0 <= beta < 1 and step >= 1
            step_sizes = [-(lr / (1 - beta1 ** t)) for (_, lr), t in zip(members, steps)]
            bias2_sqrt = [(1 - beta2 ** t) ** 0.5 for t in steps]
            denoms = torch._foreach_sqrt(exp_avg_sqs)
            torch._foreach_div_(denoms, bias2_sqrt)
            torch._foreach_add_(denoms, eps)
            torch._foreach_addcdiv_(params, exp_avgs, denoms, step_sizes)

    def state_dict(self) -> dict[str, Any]:
        """torch.optim's layout: parameters are numbered in group order."""
        index: dict[int, int] = {}
        groups = []
        for g in self.param_groups:
            ids = []
            for p in g["params"]:
                index.setdefault(id(p), len(index))
                ids.append(index[id(p)])
            groups.append({**{k: v for k, v in g.items() if k != "params"}, "params": ids})
        state = {index[id(p)]: dict(s) for p, s in self.state.items() if id(p) in index}
        return {"state": state, "param_groups": groups}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restore options and moments saved by `state_dict()` (or torch.optim.Adam's) for the same
        groups of the same shapes; moments are copied to each parameter's dtype and device."""
        saved = state_dict["param_groups"]
        if len(saved) != len(self.param_groups) or any(len(s["params"]) != len(g["params"])
                                                       for s, g in zip(saved, self.param_groups)):
            have = [len(g["params"]) for g in self.param_groups]
            raise ValueError("Adam state: its parameter groups do not match this optimiser's "
                             f"({[len(s['params']) for s in saved]} parameters per group, not {have})")
        params = {i: p for s, g in zip(saved, self.param_groups) for i, p in zip(s["params"], g["params"])}
        self.state = {}
        for i, s in state_dict["state"].items():
            p = params[int(i)]
            # copies: a state_dict from another live optimiser must not share its moments
            self.state[p] = {k: (v.to(torch.float32, copy=True) if k == "step"
                                 else v.to(dtype=p.dtype, device=p.device, copy=True)) for k, v in s.items()}
        for s, g in zip(saved, self.param_groups):
            g.update({k: v for k, v in s.items() if k != "params"})
            g["betas"] = tuple(g["betas"])
