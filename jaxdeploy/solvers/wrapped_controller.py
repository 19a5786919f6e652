"""A step-size controller that wraps another adaptive one (`LocateEvents`).

diffrax asks an adaptive controller for its `rtol`, `atol` and `norm` (e.g. to couple an
implicit solver's root-finder tolerances to them) and calls `wrap(direction)` on it before
integrating; a wrapper must answer with its inner controller's values and wrap that inner
controller, or diffrax would see neither. Subclasses add their own `init` and
`adapt_step_size` around `self.controller`.
"""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx


class WrappedController(dfx.AbstractAdaptiveStepSizeController):
    """Base of the controllers that wrap `controller` (an adaptive diffrax controller)."""

    controller: eqx.AbstractVar[dfx.AbstractAdaptiveStepSizeController]

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def atol(self):
        return self.controller.atol

    @property
    def norm(self):
        return self.controller.norm

    def wrap(self, direction):
        return eqx.tree_at(lambda c: c.controller, self, self.controller.wrap(direction))
