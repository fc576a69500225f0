"""The inflarm systems, on top of the seven packages: the launcher, launch files and RViz
configuration, and the tools that join the algorithms with the simulated or real robots (the
algorithm packages never import the hardware package, nor it them)."""
