"""The workshop's reference solutions, which the classroom's stations run (appsim.workshop.solutions)."""
