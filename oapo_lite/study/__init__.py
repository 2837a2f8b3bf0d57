"""The reproduction, in the order data flows: ``grid`` (every figure's runs, metric and claims)
-> ``experiments`` (the run cache; ``executors`` train what is missing) -> ``statistics``
(interval estimates) -> ``verdicts`` (the decision rule) -> ``claims`` (every claim judged) ->
``plotting``; ``reproduce`` runs it all and the notebooks, ``book`` makes them a site.
Notebook aids: ``quoted`` (numbers a text quotes, checked), ``interactive`` (sliders); the
studies of issues 12 and 31: ``layout_study``, ``gate_study``."""
