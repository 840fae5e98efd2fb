"""The workshop's starters: each exercise as the student gets it, TODOs in place (appsim.workshop.exercises)."""
