"""Results: the Result object and its serialisations (dict, DataFrame, files), plots."""
