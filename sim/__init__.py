"""objsearch.sim"""
