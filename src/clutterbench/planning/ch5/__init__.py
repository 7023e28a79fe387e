"""Chapter 5's planning: replenishment."""
