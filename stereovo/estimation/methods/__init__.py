"""The named methods, one module per paper: its role classes, its option declarations, its registration.

- :mod:`~stereovo.estimation.methods.mlesac`: ``mlesac``, ``guided-mlesac``;
- :mod:`~stereovo.estimation.methods.prosac`: ``prosac``;
- :mod:`~stereovo.estimation.methods.tdd`: ``r-ransac`` (the T(d,d) pre-test);
- :mod:`~stereovo.estimation.methods.sprt`: ``waldsac`` (the SPRT);
- :mod:`~stereovo.estimation.methods.lo`: ``lo-ransac`` (LO+);
- :mod:`~stereovo.estimation.methods.preemptive`: ``preemptive``;
- :mod:`~stereovo.estimation.methods.usac`: ``usac`` (PROSAC, SPRT and LO+ composed);
- :mod:`~stereovo.estimation.methods.clique`: ``inlier-detection`` (maximum clique);
- :mod:`~stereovo.estimation.methods.bansac`: ``bansac``, ``p-bansac``;
- :mod:`~stereovo.estimation.methods.ars`: ``ars``.

Importing this package registers them, in the order above (the order of
:func:`~stereovo.estimation.registry.available_methods` and of the baseline report), and then
the ``+`` variants of :mod:`stereovo.estimation.recipes`, whose bases must be registered first, and
``probabilistic+sprt`` (:data:`~stereovo.estimation.methods.sprt.PROBABILISTIC_SPRT`).
"""

# isort: off  (one import a line, in the registration order above: the reports' row order)
from stereovo.estimation.methods import mlesac  # noqa: F401
from stereovo.estimation.methods import prosac  # noqa: F401
from stereovo.estimation.methods import tdd  # noqa: F401
from stereovo.estimation.methods import sprt  # noqa: F401
from stereovo.estimation.methods import lo  # noqa: F401
from stereovo.estimation.methods import preemptive  # noqa: F401
from stereovo.estimation.methods import usac  # noqa: F401
from stereovo.estimation.methods import clique  # noqa: F401
from stereovo.estimation.methods import bansac  # noqa: F401
from stereovo.estimation.methods import ars  # noqa: F401
# isort: on
from stereovo.estimation.recipes import register_enhanced_variants
from stereovo.estimation.registry import register_method

register_enhanced_variants()
register_method(**sprt.PROBABILISTIC_SPRT)(sprt.build_probabilistic_sprt)
