"""Running a plan: execution on a cell or the twin, its result document, taking a structure apart."""
