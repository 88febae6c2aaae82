"""Studies of the paper's evaluation methodology and the executor that runs them."""
