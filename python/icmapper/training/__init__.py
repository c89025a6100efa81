"""Training of the icmapper networks: TOML configs, the stage 1 / stage 2 loops, distributed
helpers, checkpoints and the ``icmapper train`` command."""
