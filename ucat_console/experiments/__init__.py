"""The paper's experiments E1-E5 and their reports."""
