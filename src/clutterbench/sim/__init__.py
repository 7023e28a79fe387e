"""SAPIEN 3 shelf simulation: shelf, box catalogues, scene families, actions, rendering."""
