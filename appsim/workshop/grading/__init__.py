"""Grading a class: the submissions read safely (`submissions`), each exercise graded in a sandboxed worker
(`grade`, `worker`), the grades kept where only the grader writes, resumable and not forgeable (`results`).
"""
