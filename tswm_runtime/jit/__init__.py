"""numba plumbing, apart from the numerical methods: the signatures of a model's functions, the
named structures the kernels take, borrowed views, functions handed over as addresses, the
cache guard that notices edited kernels, and the cold-start notice. Imports only common/."""
