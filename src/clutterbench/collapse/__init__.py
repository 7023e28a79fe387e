"""Training, evaluating and running the collapse networks (thesis 5.2.2, 5.3.1, 6.2.1)."""
