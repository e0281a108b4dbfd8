"""roachplan: decide, by physics simulation, which path a small legged robot should take.

The installed package holds the repository's top-level folders as subpackages (pyproject's
`package-dir`): `roachplan.scenes`, `roachplan.perception`, `roachplan.planning`,
`roachplan.sim`, `roachplan.experiments` and `roachplan.app` (the CLI and the browser app).
"""

__version__ = "0.1.0"
