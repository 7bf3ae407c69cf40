"""Scenes: the question a simulation asks of a model, and the reduction passes it allows."""
