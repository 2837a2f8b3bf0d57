"""The exact track: ``exact`` (closed-form quantities of a small Dec-POMDP: returns,
advantages, KL, Lemma 1's bound) and ``algorithm1`` (Algorithm 1 with softmax tables on them)."""
