# The one place that finds third-party dependencies. All come from Debian packages installed by
# scripts/setup.sh; nothing is downloaded at configure or build time.
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(TBB REQUIRED)
find_package(TinyGLTF REQUIRED)
find_package(tinyobjloader REQUIRED)
find_package(nanoflann REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(STB REQUIRED IMPORTED_TARGET stb)
find_package(CLI11 REQUIRED)
find_package(Threads REQUIRED)
# gzip: PandaSet's .pkl.gz files, CLIP's published BPE vocabulary.
find_package(ZLIB REQUIRED)
# The fuzz build (SYNTHDRIVE_FUZZ) compiles only core, io and datasets: none of what follows.
if(NOT SYNTHDRIVE_FUZZ)
  find_package(embree 3 REQUIRED)
  # Asset mining: FAISS (Debian's static libfaiss, which links OpenMP and BLAS) searches the embedding index;
  # libcurl fetches URL-list images.
  find_package(OpenMP REQUIRED)
  find_package(faiss REQUIRED)
  find_package(CURL REQUIRED)
  # The asset bank: a SQLite catalogue; OpenSSL's EVP hashes the catalogued files (SHA-256).
  find_package(SQLite3 REQUIRED)
  find_package(OpenSSL REQUIRED)
endif()
# LibTorch runs the learned stages (src/models). Debian's libtorch-dev is CPU-only; a CUDA LibTorch found
# through CMAKE_PREFIX_PATH builds the same code for the GPU.
if(SYNTHDRIVE_WITH_TORCH)
  find_package(Torch REQUIRED)
endif()
# The Python that has torch (Debian's python3-torch lives in /usr/bin/python3, not in a pyenv or venv python
# earlier on PATH): it builds the tiny test models and runs the importer tests. Absent -> those tests skip.
if(SYNTHDRIVE_BUILD_TESTS AND NOT DEFINED SYNTHDRIVE_TORCH_PYTHON)
  foreach(candidate /usr/bin/python3 python3)
    find_program(python_candidate NAMES ${candidate} NO_CACHE)
    if(python_candidate)
      execute_process(COMMAND ${python_candidate} -c "import torch" RESULT_VARIABLE no_torch
                      OUTPUT_QUIET ERROR_QUIET)
      if(no_torch EQUAL 0)
        set(SYNTHDRIVE_TORCH_PYTHON ${python_candidate} CACHE FILEPATH "python3 with torch, for model tests")
        break()
      endif()
    endif()
    unset(python_candidate)
  endforeach()
  if(NOT SYNTHDRIVE_TORCH_PYTHON)
    message(STATUS "No python3 with torch: the model tests that need tiny TorchScript models will skip")
  endif()
endif()
# The Python with numpy and pandas (Debian's python3-numpy and python3-pandas, in /usr/bin/python3): the pickle
# tests (src/io) write their reference pickles with it and check that it loads ours. Absent -> those tests skip.
if(SYNTHDRIVE_BUILD_TESTS AND NOT DEFINED SYNTHDRIVE_PANDAS_PYTHON)
  foreach(candidate /usr/bin/python3 python3)
    find_program(python_candidate NAMES ${candidate} NO_CACHE)
    if(python_candidate)
      execute_process(COMMAND ${python_candidate} -c "import numpy, pandas" RESULT_VARIABLE no_pandas
                      OUTPUT_QUIET ERROR_QUIET)
      if(no_pandas EQUAL 0)
        set(SYNTHDRIVE_PANDAS_PYTHON ${python_candidate} CACHE FILEPATH "python3 with numpy and pandas, for pickle tests")
        break()
      endif()
    endif()
    unset(python_candidate)
  endforeach()
  if(NOT SYNTHDRIVE_PANDAS_PYTHON)
    message(STATUS "No python3 with numpy and pandas: the pickle tests that need them will skip")
  endif()
endif()
if(SYNTHDRIVE_BUILD_TESTS)
  find_package(GTest REQUIRED)
  include(GoogleTest)
endif()
if(SYNTHDRIVE_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()
