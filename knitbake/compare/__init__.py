"""The strip renderer against the reference: image metrics and the comparison report."""
