"""Online mapping: the IC-Mapper pipeline (mapper), inference association (tracker), the noisy-GT
oracle detection source (oracle), baselines, and the `map` / `compare` commands (cli)."""

# The baselines register themselves in mapping.methods on import (the registry never imports
# them); the learned mapper's variants are registered by mapping.methods itself, first.
import icmapper.mapping.methods  # noqa: E402, F401  # isort: skip
import icmapper.mapping.baselines  # noqa: E402, F401  # isort: skip
