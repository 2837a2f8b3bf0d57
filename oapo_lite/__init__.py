"""oapo-lite: off-agent trust-region policy optimisation (OAPPO / OATRPO), small and tested.

The package in layers; a layer imports only from the layers below it (``tests/test_layers.py``):

    __main__   the command line (train, reproduce, book)
    study/     the reproduction: the catalogue of figures and the grid's types, the run cache
               and executors, statistics, the verdict rule and the tables beside it, the
               claims, plots, the notebooks' runner and book
    neural/    the neural track: configs, networks, losses, rollouts, the two algorithm
               families behind one learner protocol, the training loop
    tabular/   the exact track: closed-form Dec-POMDP quantities, Algorithm 1 on softmax tables
    (shared)   envs/ (every engine behind one vector interface, the mazes' pictures), algorithms
               (the algorithm table), reuse (Eq. 9), store (files that survive a kill), cli
               (errors as one line), renamed (retired keywords refused by their new names)

``study`` reads ``neural`` (the notebooks read ``tabular`` too); ``neural`` and ``tabular``
never read each other.
"""
