"""Import OMPL's bindings once, safely.

The ompl 1.7.0 wheel ships libompl twice: the copy auditwheel vendored under ompl.libs/ (which the
extension modules link to) and a stray site-packages/libompl.so that ompl.util's `dll_loader`
loads with RTLD_GLOBAL. With both loaded, their static destructors run twice and every process
that imported OMPL dies at exit (SIGSEGV / "free(): invalid pointer"). The vendored copy is
loaded by the extensions themselves, so we skip the loader.
"""

from typing import Any

import ompl

ompl.dll_loader = lambda lib, path: None

from ompl import base as _base  # noqa: E402
from ompl import geometric as _geometric  # noqa: E402
from ompl import util as _util  # noqa: E402

# The bindings are compiled (Py++ / Boost.Python) and carry no type information: to a type
# checker their classes are unknown attributes, so the modules are typed as Any here, once.
ob: Any = _base
og: Any = _geometric
ou: Any = _util

__all__ = ["ob", "og", "ou"]
