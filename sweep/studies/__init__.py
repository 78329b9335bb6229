"""Studies of the paper built on the solver and the campaign engine: the reference run against the paper's
figures (``reference``), the fidelity study (``fidelity``), labels over realizations (``label_agreement``),
separatrices over crack thresholds (``threshold_sensitivity``) and the benchmarks (``bench``, ``dchfrac
bench``).  A new study of committed results goes here, as a module with a test and a CLI entry."""
