"""One module per reproduced study; each returns the paper's tables as arrays and rows."""
