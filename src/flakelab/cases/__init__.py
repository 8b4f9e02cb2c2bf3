"""Refinish cases: the database, the synthetic case generator, import and export."""
