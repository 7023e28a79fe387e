"""Chapter 3's trials: Yamakuzushi games (Fig. 3.15)."""
