"""A plan from an allocation: `plan_assembly` (verified by GAMP), re-allocation on a dead end,
and the course-by-course line for large structures."""
