#include "io/gmsh_mesh.hpp"

#include <dlfcn.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <exception>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "io/gmsh_library.hpp"

namespace tissue {
namespace {

// Names for messages (Gmsh's element types 1-31).
std::string type_name(int type, int nodes) {
  switch (type) {
    case 1: return "2-node line";
    case 2: return "3-node triangle";
    case 3: return "4-node quadrangle";
    case 4: return "4-node tetrahedron";
    case 5: return "8-node hexahedron";
    case 6: return "6-node prism";
    case 7: return "5-node pyramid";
    case 9: return "6-node triangle";
    case 11: return "10-node tetrahedron";
    case 15: return "point";
    default: return fmt::format("{}-node element", nodes);
  }
}

// The module (io/gmsh_library.hpp), loaded once: from $TISSUE_GMSH_MODULE, else where the build put it.
struct Module {
  gmsh_module::ReadFunction read = nullptr;
  gmsh_module::VersionFunction version = nullptr;
  std::string error;  // why it could not be loaded
};

const Module& module() {
  static Module m;
  static std::once_flag once;
  std::call_once(once, [] {
    const char* env = std::getenv("TISSUE_GMSH_MODULE");
    const std::string file = env && *env ? env : TISSUE_GMSH_MODULE;
    void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);  // never closed: Gmsh stays loaded
    if (!handle) {
      const char* e = dlerror();
      m.error = fmt::format("cannot load tissue's Gmsh module ({}; set TISSUE_GMSH_MODULE to libtissue_gmsh.so)",
                            e ? e : file);
      return;
    }
    m.read = reinterpret_cast<gmsh_module::ReadFunction>(dlsym(handle, "tissue_gmsh_read"));
    m.version = reinterpret_cast<gmsh_module::VersionFunction>(dlsym(handle, "tissue_gmsh_version"));
    if (!m.read || !m.version) m.error = fmt::format("{} is not tissue's Gmsh module", file);
  });
  return m;
}

// Gmsh runs in a child process (forked by every rank that reads), which sends its model back through a pipe:
// Gmsh trusts the counts and tags of a binary file, and on a corrupt one it may crash, call exit or run away;
// then the child dies and the run ends with one line (exit 2), as for any bad mesh. The libraries are also loaded
// in the child only, so that the run's memory holds none of Gmsh (44 MB of libraries, and its model of the file).
// The child makes no MPI call and leaves through _exit (as io/isolated_parse.cpp's do).
// How long the child may take: for a .msh 60 s and 1 s per MB (Gmsh reads tens of MB a second; a corrupt binary
// count can send it into a loop), for a .geo (meshing takes what it takes) no limit; $TISSUE_GMSH_SECONDS for both.
double time_limit(const std::string& path, bool geometry) {
  const char* env = std::getenv("TISSUE_GMSH_SECONDS");
  if (env && *env) {
    char* end = nullptr;
    const double s = std::strtod(env, &end);
    if (*end == '\0' && s > 0) return s;
  }
  if (geometry) return 0;  // none
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  return 60.0 + (ec ? 0.0 : static_cast<double>(bytes) / 1e6);
}
constexpr char kModel = 'M', kError = 'E';
// Elements per chunk of a block on the pipe: what the parent holds of Gmsh's element arrays at a time (2.6 MB of
// tetrahedra).
constexpr std::size_t kElementsPerChunk = 1 << 16;

class PipeWriter {
public:
  explicit PipeWriter(int fd) : fd_(fd) { buffer_.reserve(1 << 20); }
  void bytes(const void* p, std::size_t n) {
    const char* c = static_cast<const char*>(p);
    if (buffer_.size() + n > (1u << 20)) flush();
    if (n > (1u << 20)) return all(c, n);
    buffer_.insert(buffer_.end(), c, c + n);
  }
  template <class T> void value(T v) { bytes(&v, sizeof v); }
  template <class T> void array(const std::vector<T>& v) {
    value<std::uint64_t>(v.size());
    bytes(v.data(), v.size() * sizeof(T));
  }
  void string(const std::string& s) {
    value<std::uint64_t>(s.size());
    bytes(s.data(), s.size());
  }
  void flush() {
    all(buffer_.data(), buffer_.size());
    buffer_.clear();
  }

private:
  void all(const char* c, std::size_t n) {
    while (n > 0) {
      const ssize_t w = ::write(fd_, c, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) ::_exit(3);  // the parent is gone
      c += w, n -= static_cast<std::size_t>(w);
    }
  }
  int fd_;
  std::vector<char> buffer_;
};

[[noreturn]] void child(int fd, const std::string& path, double mesh_size, bool geometry) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  // PETSc's handlers would print a stack and call MPI_Abort (no MPI in the child): a fault kills the child.
  for (int s : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS, SIGALRM, SIGTERM, SIGINT, SIGPIPE})
    std::signal(s, SIG_DFL);
  PipeWriter out(fd);
  std::string error;
  gmsh_module::Model model;
  try {
    const Module& gmsh = module();
    if (gmsh.read)
      gmsh.read(path, mesh_size, geometry, model, error);
    else
      error = gmsh.error;
  } catch (const std::exception& e) {
    error = e.what();
  } catch (...) {
    error = "an unknown error";
  }
  if (!error.empty()) {
    out.value(kError);
    out.string(error);
  } else {
    out.value(kModel);
    out.array(model.node_tags);
    out.array(model.coords);
    out.value<std::uint8_t>(model.partitioned);
    out.value<std::uint64_t>(model.physical_names.size());
    for (const auto& [key, name] : model.physical_names) {
      out.value<std::int32_t>(key.first), out.value<std::int32_t>(key.second);
      out.string(name);
    }
    out.value<std::uint64_t>(model.blocks.size());
    for (const auto& b : model.blocks) {
      for (int v : {b.dim, b.entity, b.type, b.nodes_per_element}) out.value<std::int32_t>(v);
      out.array(b.physical);
      // Tags and nodes interleaved in chunks, so that the parent converts a chunk at a time (its memory, not
      // the child's, is the rank's).
      const std::size_t count = b.tags.size(), npe = static_cast<std::size_t>(b.nodes_per_element);
      out.value<std::uint64_t>(count), out.value<std::uint64_t>(b.nodes.size()), out.value<std::uint64_t>(b.tags[0]);
      if (b.nodes.size() != npe * count) continue;  // the parent refuses it from the counts
      for (std::size_t e0 = 0; e0 < count; e0 += kElementsPerChunk) {
        const std::size_t e1 = std::min(count, e0 + kElementsPerChunk);
        out.bytes(b.tags.data() + e0, (e1 - e0) * sizeof(std::size_t));
        out.bytes(b.nodes.data() + npe * e0, npe * (e1 - e0) * sizeof(std::size_t));
      }
    }
  }
  out.flush();
  ::_exit(0);
}

// Reads what the child sends, to a deadline; false at the end of the pipe, on an error or past the deadline.
class PipeReader {
public:
  PipeReader(int fd, std::chrono::steady_clock::time_point deadline) : fd_(fd), deadline_(deadline) {}
  bool bytes(void* p, std::size_t n) {
    char* c = static_cast<char*>(p);
    while (n > 0) {
      const double left = std::chrono::duration<double>(deadline_ - std::chrono::steady_clock::now()).count();
      if (left <= 0) return timed_out_ = true, false;
      pollfd q{fd_, POLLIN, 0};
      const int ready = ::poll(&q, 1, static_cast<int>(std::min(left, 3600.0) * 1000) + 1);
      if (ready < 0 && errno == EINTR) continue;
      if (ready < 0) return false;
      if (ready == 0) continue;
      const ssize_t r = ::read(fd_, c, n);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      c += r, n -= static_cast<std::size_t>(r);
    }
    return true;
  }
  template <class T> bool value(T& v) { return bytes(&v, sizeof v); }
  template <class T> bool array(std::vector<T>& v) {
    std::uint64_t n = 0;
    if (!value(n) || n > (std::uint64_t(1) << 40) / sizeof(T)) return false;
    v.resize(n);
    return bytes(v.data(), n * sizeof(T));
  }
  bool string(std::string& s) {
    std::uint64_t n = 0;
    if (!value(n) || n > (1u << 20)) return false;
    s.resize(n);
    return bytes(s.data(), n);
  }
  bool timed_out() const { return timed_out_; }

private:
  int fd_;
  std::chrono::steady_clock::time_point deadline_;
  bool timed_out_ = false;
};

// Node tag -> index into Gmsh's node arrays: dense when the tags are (Gmsh numbers nodes 1..n), hashed otherwise.
class NodeIndex {
public:
  explicit NodeIndex(const std::vector<std::size_t>& tags) {
    std::size_t max = 0;
    for (auto t : tags) max = std::max(max, t);
    dense_ = max <= 4 * tags.size() + 1024;
    if (dense_) {
      slot_.assign(max + 1, -1);
      for (std::size_t i = 0; i < tags.size(); ++i) slot_[tags[i]] = static_cast<std::int64_t>(i);
    } else {
      for (std::size_t i = 0; i < tags.size(); ++i) map_[tags[i]] = static_cast<std::int64_t>(i);
    }
  }
  std::int64_t operator()(std::size_t tag) const {
    if (dense_) return tag < slot_.size() ? slot_[tag] : -1;
    auto it = map_.find(tag);
    return it == map_.end() ? -1 : it->second;
  }

private:
  bool dense_;
  std::vector<std::int64_t> slot_;
  std::unordered_map<std::size_t, std::int64_t> map_;
};

// Gmsh's model into a TetMesh as it comes through the pipe, a chunk of elements at a time: rank 0 reads every
// rank's mesh, so it never holds Gmsh's element arrays whole, nor a second copy of the tetrahedra (#21's memory
// target). The tetrahedra keep Gmsh's node indices until finish() numbers the molecules.
class Converter {
public:
  Converter(const std::string& path, bool geometry) : path_(path), geometry_(geometry) { mesh_.file = path; }

  // Gmsh's model as far as it has come: the nodes, names and partitioning (no blocks).
  gmsh_module::Model& model() { return model_; }

  // The nodes, names and partitioning have come; checks them.
  void begin() {
    const gmsh_module::Model& model = model_;
    if (model.partitioned)  // its entities and their order are the partitioning's, not the model's
      throw InputError(path_, "", "a partitioned mesh; save it unpartitioned (tissue partitions it itself)");
    if (model.coords.size() != 3 * model.node_tags.size())
      throw InputError(path_, "", fmt::format("Gmsh gave {} coordinates for {} nodes", model.coords.size(),
                                              model.node_tags.size()));
    index_ = std::make_unique<NodeIndex>(model.node_tags);
  }

  // A block's header; false: the block does not count (its elements are read and dropped).
  bool block(const gmsh_module::Block& b, std::uint64_t count, std::uint64_t node_count, std::size_t first_tag) {
    // A volume of a .msh counts always (the file holds what was saved); of a .geo as Gmsh saves it: only
    // physical ones once the model has a physical group (Mesh.SaveAll = 0). Surfaces come physical only.
    if (b.dim == 3 && b.physical.empty() && geometry_ && !model_.physical_names.empty()) return false;
    if (b.dim == 3 && b.type != 4)
      throw InputError(path_, "", fmt::format("element {} is of type {} ({}); only 4-node tetrahedra (type 4) are "
                                              "supported", first_tag, b.type, type_name(b.type, b.nodes_per_element)));
    if (b.dim == 2 && b.type != 2)
      throw InputError(path_, "", fmt::format("element {} on a physical surface is of type {} ({}); only 3-node "
                                              "triangles (type 2) bound a tetrahedral mesh", first_tag, b.type,
                                              type_name(b.type, b.nodes_per_element)));
    const std::uint64_t nn = b.dim == 3 ? 4 : 3;
    if (node_count != nn * count)
      throw InputError(path_, "", fmt::format("Gmsh gave {} node tags for {} elements of type {}", node_count, count,
                                              b.type));
    dim_ = b.dim;
    physical_ = b.physical;
    if (dim_ == 3) mesh_.tets.reserve(mesh_.tets.size() + count), tet_physical_.reserve(tet_physical_.size() + count);
    return true;
  }

  // `n` elements of the current block: their tags and nodes.
  void elements(const std::size_t* tags, const std::size_t* nodes, std::size_t n) {
    const std::size_t nn = dim_ == 3 ? 4 : 3;
    for (std::size_t e = 0; e < n; ++e) {
      const std::size_t* t = nodes + nn * e;
      std::array<std::int64_t, 4> i{};
      for (std::size_t k = 0; k < nn; ++k) i[k] = node(t[k], tags[e]);
      if (dim_ == 3) {
        const double vol = signed_volume(position(i[0]), position(i[1]), position(i[2]), position(i[3]));
        if (!(vol > 0))
          throw InputError(path_, "", fmt::format("tetrahedron {} is {} (volume {:.3e}; Gmsh orders a tetrahedron's "
                                                  "nodes so that its volume is positive)",
                                                  tags[e], vol < 0 ? "inverted" : "flat", vol));
        mesh_.tets.push_back(i);
        tet_physical_.push_back(physical_.empty() ? -1 : physical_.front());
      } else {
        for (int p : physical_) surface_[p].push_back({i[0], i[1], i[2]});
      }
    }
  }

  // Molecules: the nodes the tetrahedra use, in tag order.
  TetMesh finish() {
    if (mesh_.tets.empty())
      throw InputError(path_, "", "no tetrahedra (mesh the volume, gmsh -3, and put it in a physical volume)");
    index_.reset();
    const std::vector<std::size_t>& tag = model_.node_tags;
    std::vector<std::int64_t> molecule(tag.size(), -1);  // Gmsh's node index -> molecule
    for (const auto& T : mesh_.tets)
      for (auto i : T) molecule[i] = 0;
    std::vector<std::int64_t> used;
    for (std::size_t i = 0; i < molecule.size(); ++i)
      if (molecule[i] == 0) used.push_back(static_cast<std::int64_t>(i));
    std::sort(used.begin(), used.end(), [&](std::int64_t x, std::int64_t y) { return tag[x] < tag[y]; });
    mesh_.nodes.reserve(used.size());
    for (auto i : used) {
      molecule[i] = static_cast<std::int64_t>(mesh_.nodes.size());
      mesh_.nodes.push_back(position(i));
    }
    std::vector<std::int64_t>().swap(used), std::vector<double>().swap(model_.coords);  // freed (`= {}` keeps the capacity)
    for (auto& T : mesh_.tets)
      for (auto& i : T) i = molecule[i];
    auto label = [&](int dim, int t) {
      auto it = model_.physical_names.find({dim, t});
      return it != model_.physical_names.end() && !it->second.empty() ? it->second : std::to_string(t);
    };
    std::map<int, int> region_index;  // physical tag -> index in region_names
    for (int& r : tet_physical_) {
      if (r < 0) continue;
      auto [it, added] = region_index.emplace(r, static_cast<int>(mesh_.region_names.size()));
      if (added) mesh_.region_names.push_back(label(3, r));
      r = it->second;
    }
    mesh_.tet_region = std::move(tet_physical_);
    for (const auto& [physical, triangles] : surface_) {
      TetMesh::Surface s;
      s.name = label(2, physical);
      s.triangles.reserve(triangles.size());
      for (const auto& tri : triangles) {
        std::array<std::int64_t, 3> v;
        for (int k = 0; k < 3; ++k) {
          if (molecule[tri[k]] < 0)
            throw InputError(path_, "", fmt::format("physical surface \"{}\" has node {}, which no tetrahedron uses",
                                                    s.name, tag[tri[k]]));
          v[k] = molecule[tri[k]];
        }
        s.triangles.push_back(v);
      }
      mesh_.surfaces.push_back(std::move(s));
    }
    return std::move(mesh_);
  }

private:
  std::int64_t node(std::size_t tag, std::size_t element) const {
    const std::int64_t i = (*index_)(tag);
    if (i < 0)
      throw InputError(path_, "", fmt::format("element {} names node {}, which the mesh does not define", element, tag));
    return i;
  }
  Vec3 position(std::int64_t i) const {
    const auto& c = model_.coords;
    return {c[3 * i], c[3 * i + 1], c[3 * i + 2]};
  }

  std::string path_;
  bool geometry_;
  gmsh_module::Model model_;
  std::unique_ptr<NodeIndex> index_;
  int dim_ = 0;
  std::vector<int> physical_;  // the current block's
  TetMesh mesh_;
  std::vector<int> tet_physical_;  // per tetrahedron: its physical volume, -1: none (then its region)
  std::map<int, std::vector<std::array<std::int64_t, 3>>> surface_;  // physical tag -> triangles (node indices)
};

// The model from the child into `to`; false if it is incomplete (or `error`: Gmsh's). Throws the Converter's
// InputError as soon as an element is refused.
bool receive(PipeReader& in, Converter& to, std::string& error) {
  gmsh_module::Model& model = to.model();
  char kind = 0;
  if (!in.value(kind)) return false;
  if (kind == kError) return in.string(error) && !error.empty();
  if (kind != kModel) return false;
  std::uint8_t partitioned = 0;
  std::uint64_t names = 0, blocks = 0;
  if (!in.array(model.node_tags) || !in.array(model.coords) || !in.value(partitioned) || !in.value(names))
    return false;
  model.partitioned = partitioned != 0;
  for (std::uint64_t i = 0; i < names; ++i) {
    std::int32_t dim = 0, tag = 0;
    std::string name;
    if (!in.value(dim) || !in.value(tag) || !in.string(name)) return false;
    model.physical_names[{dim, tag}] = name;
  }
  if (!in.value(blocks)) return false;
  to.begin();
  std::vector<std::size_t> tags, nodes;  // one chunk
  for (std::uint64_t i = 0; i < blocks; ++i) {
    gmsh_module::Block b;
    std::int32_t v[4];
    for (auto& x : v)
      if (!in.value(x)) return false;
    b.dim = v[0], b.entity = v[1], b.type = v[2], b.nodes_per_element = v[3];
    std::uint64_t count = 0, node_count = 0, first_tag = 0;
    if (!in.array(b.physical) || !in.value(count) || !in.value(node_count) || !in.value(first_tag)) return false;
    const bool keep = to.block(b, count, node_count, first_tag);
    const std::uint64_t npe = static_cast<std::uint64_t>(std::max(b.nodes_per_element, 0));
    if (node_count != npe * count) return false;  // (a kept block's counts are checked by the Converter)
    for (std::uint64_t e0 = 0; e0 < count; e0 += kElementsPerChunk) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(kElementsPerChunk, count - e0));
      tags.resize(n), nodes.resize(npe * n);
      if (!in.bytes(tags.data(), n * sizeof(std::size_t)) || !in.bytes(nodes.data(), npe * n * sizeof(std::size_t)))
        return false;
      if (keep) to.elements(tags.data(), nodes.data(), n);
    }
  }
  char end = 0;
  return !in.value(end);  // nothing after the model
}

void read_in_child(const std::string& path, double mesh_size, bool geometry, Converter& to) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw InputError(path, "", std::string("cannot create a pipe to read the mesh in a child process: ") +
                                   std::strerror(errno));
  std::fflush(nullptr);  // else the child's copies of unflushed stdio buffers could be written twice
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]), ::close(fds[1]);
    throw InputError(path, "", std::string("cannot fork to read the mesh in a child process: ") + std::strerror(err));
  }
  if (pid == 0) {
    ::close(fds[0]);
    child(fds[1], path, mesh_size, geometry);
  }
  ::close(fds[1]);
  const double seconds = time_limit(path, geometry);
  const auto deadline = seconds <= 0 ? std::chrono::steady_clock::time_point::max()
                                     : std::chrono::steady_clock::now() + std::chrono::duration_cast<
                                           std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
  PipeReader in(fds[0], deadline);
  std::string error;
  bool complete = false;
  std::exception_ptr refused;  // the Converter's verdict on an element (or out of memory)
  try {
    complete = receive(in, to, error);
  } catch (...) {
    refused = std::current_exception();
  }
  ::close(fds[0]);
  if (in.timed_out() || refused) ::kill(pid, SIGKILL);
  int status = 0;
  pid_t reaped;
  while ((reaped = ::waitpid(pid, &status, 0)) < 0 && errno == EINTR) {
  }
  if (refused) std::rethrow_exception(refused);
  const std::string tail = " (in the child process that reads it): a corrupt or crafted file?";
  if (in.timed_out())
    throw InputError(path, "", fmt::format("Gmsh did not finish reading it in {:g} s{}", seconds, tail));
  if (reaped == pid && WIFSIGNALED(status))
    throw InputError(path, "", fmt::format("Gmsh died with signal {} ({}){}", WTERMSIG(status),
                                           strsignal(WTERMSIG(status)), tail));
  if (!complete) {  // Gmsh called exit (a .geo's Exit does), or the pipe broke
    const std::string how =
        reaped == pid && WIFEXITED(status) ? fmt::format("exited with status {}", WEXITSTATUS(status)) : "ended";
    throw InputError(path, "", fmt::format("Gmsh {} without a result{}", how, tail));
  }
  if (!error.empty()) throw InputError(path, "", error);
}

// The last line of a .msh file (ASCII or binary, every version) is the $End of its last section; a file that ends
// elsewhere was cut short (Gmsh itself would silently read some such files as a smaller mesh).
void check_complete(std::ifstream& in, const std::string& path) {
  in.clear();
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  const std::streamoff n = std::min<std::streamoff>(size, 4096);
  std::string tail(static_cast<std::size_t>(n), '\0');
  in.seekg(size - n);
  in.read(tail.data(), n);
  if (!in) throw InputError(path, "", std::string("cannot read the mesh: ") + std::strerror(errno));
  while (!tail.empty() && std::isspace(static_cast<unsigned char>(tail.back()))) tail.pop_back();
  const std::size_t nl = tail.find_last_of('\n');
  const std::string last = nl == std::string::npos ? tail : tail.substr(nl + 1);
  if (last.rfind("$End", 0) != 0)
    throw InputError(path, "", "cut short: its last line is not the $End line of a section");
}

}  // namespace

TetMesh read_gmsh(const std::string& path, double mesh_size) {
  // What the file is: a mesh begins with $MeshFormat in every version, ASCII or binary; otherwise a .geo.
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open the mesh: ") + std::strerror(errno));
  std::string head(64, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  if (in.bad()) throw InputError(path, "", std::string("cannot read the mesh: ") + std::strerror(errno));
  const std::size_t start = head.find_first_not_of(" \t\r\n");
  if (start == std::string::npos && head.size() < 64) throw InputError(path, "", "empty file, not a Gmsh mesh");
  std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : "";
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  const bool is_mesh = start != std::string::npos && head.compare(start, 11, "$MeshFormat") == 0;
  const bool geometry = !is_mesh && ext == ".geo";
  if (!is_mesh && !geometry)
    throw InputError(path, "", "not a Gmsh mesh: it must begin with $MeshFormat (or be a .geo geometry, which is "
                               "meshed at run time)");
  if (is_mesh) check_complete(in, path);
  in.close();

  Converter to(path, geometry);
  read_in_child(path, mesh_size, geometry, to);
  return to.finish();
}

TetMesh read_mesh(const BodySpec& spec) { return read_gmsh(spec.file, spec.mesh_size); }

std::string gmsh_library_version() {
  const Module& gmsh = module();
  if (!gmsh.version) return "(" + gmsh.error + ")";
  std::string version;
  gmsh.version(version);
  return version;
}

}  // namespace tissue
