"""`vlmrl study`: regimes x arms x seeds and VLM-quality variants, one regime map and report."""
