"""Report tables: our metrics with the thesis figure beside them."""
