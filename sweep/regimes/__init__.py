"""What a run is: the regime classifier (``classify``), the dimensionless numbers (``numbers``), the smooth
probabilistic regime model (``regime_model``), the separatrix fits (``separatrix``), the phase diagrams
(``diagrams``) and the classifier's code hash (``provenance``).  Imports only ``solver``; a new regime rule goes in ``classify``."""
