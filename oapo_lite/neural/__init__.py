"""The neural track, in the order data flows: ``config`` (a run's settings) -> ``rollout``
(every seat acting in a vector of env copies) -> ``learner`` (the protocol the loop drives:
``ppo_family`` for OAPPO, OATRPO, HAPPO, HATRPO, MAPPO, IPPO; ``a2c_family`` with ``seps`` for
SEAC and SePS; built on ``nets``, ``losses``, ``trpo``, ``adam``, ``adaptive``, ``normalize``;
each iteration reported as a ``learner.Update``) -> ``results`` (what a results row holds) ->
``runstate`` (what a checkpoint holds) -> ``train`` (the loop; ``board`` its TensorBoard
scalars, ``cost`` its CPU time)."""
