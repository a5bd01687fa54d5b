"""The base the other packages build on: named integer codes and small tensor contractions.

`Coded` is the base of every status and kind code of jaxgrasp (an integer with a
label and a one-line message); `contract` is a small ``einsum`` written as one
broadcast product and one sum, so that XLA fuses it with what surrounds it. The solver
and the model both use them; here, below both, neither depends on the other for them.

``__all__`` lists the names promised to users. The names imported below the comment
"For jaxgrasp's other packages" are what the library's other packages use from here
(they import from this face, never from its private modules); they are not in
``__all__`` and not promised to users.
"""

from jaxgrasp.base._codes import Coded

# For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
from jaxgrasp.base._contract import contract

__all__ = ["Coded"]
