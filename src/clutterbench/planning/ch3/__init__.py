"""Chapter 3's planning: slide selection and the POMDP of Yamakuzushi."""
