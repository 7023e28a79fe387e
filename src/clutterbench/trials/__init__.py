"""Simulated robot trials: one harness for every chapter's conditions."""
