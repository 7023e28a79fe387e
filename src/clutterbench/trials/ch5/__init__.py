"""Chapter 5's trials: replenishment (Table 5.2)."""
