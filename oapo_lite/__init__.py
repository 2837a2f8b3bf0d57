"""oapo-lite: off-agent trust-region policy optimisation (OAPPO / OATRPO), small and tested."""
