"""objsearch.agent"""
