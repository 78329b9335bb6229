"""The campaign engine: a spec (``spec_model``, ``spec``) expands into runs (``sampler``; ``boundary`` for the
adaptive boundary sampler); ``plan`` finds what the store (``store``, ``archive`` for pruning) and the committed
table (``archived``) hold for each under the results root of ``paths``; ``run`` runs the rest through
``scheduler`` and relabels; ``table`` builds the table (``columns`` declares its units), ``cost`` estimates a
dry run; ``load``, ``run_folder`` and ``compare`` read results; ``plot``, ``figures``, ``report``, ``report_html``
and ``accounting`` report them; ``cli`` is ``dchfrac campaign``.  Imports ``solver`` and ``sweep.regimes``; a new
sampler goes beside ``sampler``."""
