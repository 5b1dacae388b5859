"""From signals to properties: features, resampling, the MLP forward pass, the estimators."""
