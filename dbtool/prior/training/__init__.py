"""Training, evaluation and the model card of the prior."""
