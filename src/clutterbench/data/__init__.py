"""Dataset stages: sharded generation, splitting, and the PyTorch Dataset."""
