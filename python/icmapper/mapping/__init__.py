"""Online mapping: the IC-Mapper pipeline (mapper), inference association (tracker), the noisy-GT
oracle detection source (oracle), baselines, and the `map` / `compare` commands (cli)."""
