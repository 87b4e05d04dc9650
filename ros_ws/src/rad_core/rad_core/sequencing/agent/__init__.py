"""What /plan_assembly does for an agent: a first plan, then improvement stages under one deadline."""
