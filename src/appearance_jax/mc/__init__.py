"""Monte Carlo estimators: the position-free layered random walk (:mod:`.layered`)."""
