"""Analysis numerics usable without a rig: Allan deviation, Dahl bearing fits, run-file spectra,
and the model-gap workflow (``procedures.analysis.gap``). They read run files and arrays; they
never command hardware."""
