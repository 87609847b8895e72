"""Physical realism: does a failure found in simulation hold in a photograph of the same scene?"""
