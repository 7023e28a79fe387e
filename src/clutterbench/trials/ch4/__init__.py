"""Chapter 4's trials: pull with a supporting arm (Table 4.1)."""
