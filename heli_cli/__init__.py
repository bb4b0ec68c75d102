"""The ``heli`` command line: the last link of the chain, wiring identification, env and controllers."""
