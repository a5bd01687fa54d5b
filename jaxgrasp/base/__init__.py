"""The base the other packages build on: named integer codes, small tensor contractions
and results' numbers as JSON.

`Coded` is the base of every status and kind code of jaxgrasp (an integer with a
label and a one-line message); `contract` is a small ``einsum`` written as one
broadcast product and one sum, so that XLA fuses it with what surrounds it. The solver
and the model both use them; here, below both, neither depends on the other for them.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.base._codes import Coded

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.base._contract import contract
    from jaxgrasp.base._json import json_floats
    from jaxgrasp.base._limits import over_limit, whole_number

__all__ = ["Coded"]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
