"""The ``fbs`` command line (DESIGN.md section 7): one module per command, on top of the packages.

Data flows one way (DESIGN.md section 2): ``drivers`` -> ``daq`` -> ``procedures`` ->
``console``; this package sits above them all and only parses arguments, calls them and
prints. ``fbs.cli.main`` is the console script; ``python -m fbs`` runs the same.
"""
