"""Recovery from NaN / Inf during optimisation, for every stage loop.

After each optimiser step :meth:`StepGuard.check` looks at the loss and the parameters. When all are
finite it keeps a copy of them and of the optimiser's state; when not, it restores that last finite state,
lowers the learning rate of the groups that went bad (all groups when only the loss did), records the event
in the fit's notes (``params.json``) and the run continues. The same failure several steps in a row
stops the input with :class:`NonFiniteError`.
"""

from __future__ import annotations

import copy

import torch

RETRIES = 3  # consecutive non-finite steps tolerated before the input fails
LR_FACTOR = 0.5  # learning-rate multiplier for a group that went non-finite


class NonFiniteError(ArithmeticError):
    """The loss or the parameters stayed NaN / Inf although the learning rate was lowered (one line)."""


class StepGuard:
    """Snapshot / rollback of ``optimiser``'s parameters and state around non-finite steps."""

    def __init__(self, optimiser: torch.optim.Optimizer, stage: str, log=None, retries: int = RETRIES):
        self.optimiser, self.stage, self.log, self.retries = optimiser, stage, log, retries
        self.failures = 0  # consecutive
        self.events = 0  # total rollbacks
        self.step = 0
        self._save()

    def check(self, loss: torch.Tensor) -> bool:
        """Call after ``optimiser.step()``: True when the step is kept, False when it was rolled back."""
        self.step += 1
        bad_groups = self._bad_groups()
        if bool(torch.isfinite(loss.detach()).all()) and not bad_groups:
            self.failures = 0
            self._save()
            return True
        self._recover(bad_groups or list(range(len(self.optimiser.param_groups))))
        return False

    def _bad_groups(self) -> list[int]:
        return [index for index, group in enumerate(self.optimiser.param_groups)
                if not all(bool(torch.isfinite(p.detach()).all()) for p in group["params"])]

    def _recover(self, groups: list[int]) -> None:
        self.failures += 1
        self.events += 1
        if self.failures > self.retries:
            raise NonFiniteError(f"{self.stage}: loss or parameters became NaN/Inf at {self.failures} steps in a "
                                 f"row (step {self.step}) although the learning rate was lowered; try another "
                                 "--seed or preset")
        self._restore()
        for index in groups:
            group = self.optimiser.param_groups[index]
            for key in ("lr", "base_lr"):  # base_lr: loops that schedule lr from it (stage 1)
                if key in group:
                    group[key] *= LR_FACTOR
        message = (f"{self.stage}: non-finite loss or parameters at step {self.step}; restored the last finite "
                   f"state and halved the learning rate of parameter group(s) {groups}")
        if self.log is not None:
            self.log.info(message)

    def _save(self) -> None:
        self._params = [[p.detach().clone() for p in group["params"]] for group in self.optimiser.param_groups]
        self._state = copy.deepcopy(self.optimiser.state_dict())

    @torch.no_grad()
    def _restore(self) -> None:
        for group, saved in zip(self.optimiser.param_groups, self._params, strict=True):
            for param, value in zip(group["params"], saved, strict=True):
                param.copy_(value)
        rates = [{k: g[k] for k in ("lr", "base_lr") if k in g} for g in self.optimiser.param_groups]
        self.optimiser.load_state_dict(copy.deepcopy(self._state))
        for group, rate in zip(self.optimiser.param_groups, rates, strict=True):
            group.update(rate)  # keep rates already lowered by earlier rollbacks
