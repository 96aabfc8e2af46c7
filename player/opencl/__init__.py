"""The OpenCL plumbing every engine shares, in layers, each importing only those before it:

- :mod:`.devices`: the devices present, device choice and one context per device;
- :mod:`.programs`: ``player/kernels/*.cl`` built once per context and defines, kernels fetched once;
- :mod:`.verify`: each device's self-test verdict, found in a child process and cached;
- :mod:`.selftest`: the checks that child runs (imported only there).

Import from the modules themselves (this package re-exports nothing, so that importing one
layer never loads another).
"""
