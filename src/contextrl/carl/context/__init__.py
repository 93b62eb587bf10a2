"""CARL's ``carl.context``: context features and spaces, the sampler and the selectors."""
