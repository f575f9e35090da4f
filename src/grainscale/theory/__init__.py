"""Closed-form and quadrature predictions that the validation cases are compared against.

archimedes.py  the modified Archimedes law of Kang et al. 2018 (seed Eq. 27-29): the
               steady intrusion slope K_phi of a friction angle, and its inverse.
"""
