"""jaxtrack: differentiable state estimation for target tracking and navigation research.

Importing jaxtrack switches JAX to float64 (see :mod:`jaxtrack._config` for why and how to opt
out with ``JAXTRACK_ENABLE_X64=0``).
"""

from ._config import _enable_x64_by_default

_enable_x64_by_default()

from . import filters as filters  # noqa: E402
from . import models as models  # noqa: E402
from . import montecarlo as montecarlo  # noqa: E402
from . import covariance as covariance  # noqa: E402
from . import sensitivity as sensitivity  # noqa: E402
from . import learning as learning  # noqa: E402
from ._validation import InputError as InputError  # noqa: E402

__version__ = "0.1.0"
