"""Load scenes: what stands in each rack bay, as scene graphs by knowledge-supervised MCMC (seed 003, ch. 4)."""
