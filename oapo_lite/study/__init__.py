"""The reproduction, in the order data flows: ``figures`` (the catalogue: every figure's runs,
metric and claims, one module per engine family; ``grid`` its types) -> ``experiments`` (the
run cache; ``executors`` train what is missing) -> ``statistics`` (interval estimates) ->
``verdicts`` (the decision rule; ``tables`` the study's tables beside it) -> ``claims`` (every
claim judged) -> ``plotting`` (``palette`` its colours); ``reproduce`` runs it all and the
notebooks, ``book`` makes them a site, ``costs`` prices it. Notebook aids: ``quoted`` (numbers a
text quotes, checked), ``interactive`` (sliders). Studies beyond the paper's figures:
``layout_study`` (generated mazes), ``gate_study`` (Eq. 9's gate statistic), ``selection``
(Eq. 9's sigma on the engines)."""
