"""Our drive: its rotor-position estimator (a bench plug-in) and its controller under test."""
