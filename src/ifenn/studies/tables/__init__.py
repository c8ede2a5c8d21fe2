"""Tables read from finished runs: metrics, accuracy, speed against accuracy, finer references, adaptive resolution, specimens, the summary."""
