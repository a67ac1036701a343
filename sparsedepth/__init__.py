"""sparsedepth: depth completion by regularised optimisation with sparse linear algebra."""
