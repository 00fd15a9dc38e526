"""fbs-hil: hardware-in-the-loop DAQ and test procedures for the Fixed Base Simulator.

The subpackages live in the repository's top-level folders (DESIGN.md section 2):
``fbs.drivers``, ``fbs.simhw``, ``fbs.daq``, ``fbs.procedures``, ``fbs.console``.
"""

__version__ = "0.1.0"
