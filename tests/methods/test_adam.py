"""The harness's Adam against torch.optim.Adam: the same parameters bit for bit, torch's state_dicts
load, and no torch._dynamo import (the reason it exists)."""
from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from gsbench.train.adam import Adam

SHAPES = [(100, 3), (100,), (50, 4), (7,)]


def _pair(dtype, eps=1e-15):
    g = torch.Generator().manual_seed(0)
    ps = [torch.randn(s, generator=g, dtype=dtype) for s in SHAPES]
    a = [p.clone().requires_grad_() for p in ps]
    b = [p.clone().requires_grad_() for p in ps]
    ref = torch.optim.Adam([{"params": [p], "lr": 10.0 ** -(i + 1), "name": f"t{i}"} for i, p in enumerate(a)],
                           lr=0.0, eps=eps)
    ours = Adam([{"params": [p], "lr": 10.0 ** -(i + 1), "name": f"t{i}"} for i, p in enumerate(b)], lr=0.0, eps=eps)
    return a, b, ref, ours


def _steps(a, b, ref, ours, n, seed=1):
    g = torch.Generator().manual_seed(seed)
    for it in range(n):
        # gradients from 1e-3 to 1e3, so tiny and large second moments both occur; some tensors skip steps
        grads = [torch.randn(s, generator=g, dtype=a[0].dtype) * 10.0 ** ((it % 7) - 3) for s in SHAPES]
        for k, (p, q, gr) in enumerate(zip(a, b, grads)):
            has = (it + k) % 5 != 0
            p.grad = gr.clone() if has else None
            q.grad = gr.clone() if has else None
        ref.step()
        ours.step()
        if it == n // 2:
            for grp in ref.param_groups + ours.param_groups:
                grp["lr"] *= 0.5


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_same_parameters_as_torch_adam_bit_for_bit(dtype):
    a, b, ref, ours = _pair(dtype)
    _steps(a, b, ref, ours, 300)
    for p, q in zip(a, b):
        assert torch.equal(p, q)
    for i in range(len(SHAPES)):
        for k in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(ref.state[a[i]][k], ours.state[b[i]][k])


def test_torch_adams_state_dict_loads_and_resumes_identically():
    """Checkpoints written while the harness used torch.optim.Adam resume here."""
    a, b, ref, ours = _pair(torch.float32)
    _steps(a, b, ref, ours, 40)
    a2 = [p.detach().clone().requires_grad_() for p in a]
    ours2 = Adam([{"params": [p], "lr": 0.0, "name": f"t{i}"} for i, p in enumerate(a2)], eps=1e-15)
    ours2.load_state_dict(ref.state_dict())
    assert [g["lr"] for g in ours2.param_groups] == [g["lr"] for g in ref.param_groups]
    _steps(a, a2, ref, ours2, 30, seed=2)
    for p, p2 in zip(a, a2):
        assert torch.equal(p, p2)
    # and ours round-trips through its own state_dict
    b2 = [q.detach().clone().requires_grad_() for q in b]
    ours3 = Adam([{"params": [q], "lr": 0.0, "name": f"t{i}"} for i, q in enumerate(b2)], eps=1e-15)
    ours3.load_state_dict(ours.state_dict())
    _steps(b, b2, ours, ours3, 30, seed=2)
    for q, q2 in zip(b, b2):
        assert torch.equal(q, q2)


def test_mismatched_groups_are_refused():
    a, b, ref, ours = _pair(torch.float32)
    _steps(a, b, ref, ours, 2)
    other = Adam([torch.zeros(3, requires_grad=True)])
    with pytest.raises(ValueError, match="parameter groups do not match"):
        other.load_state_dict(ours.state_dict())
    with pytest.raises(ValueError, match="empty parameter list"):
        Adam([])


def test_zero_grad_and_parameters_without_gradients():
    p = torch.ones(4, requires_grad=True)
    q = torch.ones(2, requires_grad=True)
    opt = Adam([p, q], lr=0.1)
    p.grad = torch.ones(4)
    opt.step()
    assert torch.allclose(p, torch.full((4,), 0.9)) and torch.equal(q, torch.ones(2)) and q not in opt.state
    opt.zero_grad(set_to_none=False)
    assert torch.equal(p.grad, torch.zeros(4))
    opt.zero_grad()
    assert p.grad is None


def test_training_steps_do_not_import_dynamo():
    code = ("import sys, torch\nfrom gsbench.train.adam import Adam\n"
            "p = torch.ones(3, requires_grad=True); o = Adam([p]); (p * p).sum().backward(); o.step()\n"
            "o.zero_grad(); o.load_state_dict(o.state_dict())\n"
            "print('torch._dynamo' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
