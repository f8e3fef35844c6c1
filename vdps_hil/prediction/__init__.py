"""Prediction (paper section 6): predictor, metrics, rollover warning."""
