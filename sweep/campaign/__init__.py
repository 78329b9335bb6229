"""The campaign engine: a spec (``spec_model``, ``spec``) expands into runs (``sampler``; ``boundary`` for the
adaptive boundary sampler), the scheduler runs them (``scheduler``), each in a folder keyed by a hash
(``store``, ``archive`` for pruning), ``engine`` labels them and builds the table (``columns`` declares its
units), ``load`` and ``compare`` read it, ``figures``, ``report_html`` and ``accounting`` report it, ``cli``
is ``dchfrac campaign``.  Imports ``solver`` and ``sweep.regimes``; a new sampler goes beside ``sampler``."""
