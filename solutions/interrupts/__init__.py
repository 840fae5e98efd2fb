"""Interrupt-driven solutions of Ex1, Ex3 and Ex6: the same checks, routines marked as C18's pragmas mark them."""
