// The GL entry points the renderer uses, loaded from the context (no link-time libGL).
#pragma once

#include <GL/glcorearb.h>

#define PROBELESS_GL_FUNCTIONS(X)                                \
  X(PFNGLGETSTRINGPROC, GetString)                               \
  X(PFNGLGETERRORPROC, GetError)                                 \
  X(PFNGLENABLEPROC, Enable)                                     \
  X(PFNGLDISABLEPROC, Disable)                                   \
  X(PFNGLFRONTFACEPROC, FrontFace)                               \
  X(PFNGLCULLFACEPROC, CullFace)                                 \
  X(PFNGLDEPTHFUNCPROC, DepthFunc)                               \
  X(PFNGLDEPTHMASKPROC, DepthMask)                               \
  X(PFNGLCOLORMASKPROC, ColorMask)                               \
  X(PFNGLVIEWPORTPROC, Viewport)                                 \
  X(PFNGLCLEARCOLORPROC, ClearColor)                             \
  X(PFNGLCLEARDEPTHPROC, ClearDepth)                             \
  X(PFNGLCLEARPROC, Clear)                                       \
  X(PFNGLCLEARBUFFERFVPROC, ClearBufferfv)                       \
  X(PFNGLFINISHPROC, Finish)                                     \
  X(PFNGLPIXELSTOREIPROC, PixelStorei)                           \
  X(PFNGLREADPIXELSPROC, ReadPixels)                             \
  X(PFNGLREADBUFFERPROC, ReadBuffer)                             \
  X(PFNGLDRAWBUFFERSPROC, DrawBuffers)                           \
  X(PFNGLDRAWBUFFERPROC, DrawBuffer)                             \
  X(PFNGLCREATESHADERPROC, CreateShader)                         \
  X(PFNGLSHADERSOURCEPROC, ShaderSource)                         \
  X(PFNGLCOMPILESHADERPROC, CompileShader)                       \
  X(PFNGLGETSHADERIVPROC, GetShaderiv)                           \
  X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog)                 \
  X(PFNGLDELETESHADERPROC, DeleteShader)                         \
  X(PFNGLCREATEPROGRAMPROC, CreateProgram)                       \
  X(PFNGLATTACHSHADERPROC, AttachShader)                         \
  X(PFNGLLINKPROGRAMPROC, LinkProgram)                           \
  X(PFNGLGETPROGRAMIVPROC, GetProgramiv)                         \
  X(PFNGLGETPROGRAMINFOLOGPROC, GetProgramInfoLog)               \
  X(PFNGLDELETEPROGRAMPROC, DeleteProgram)                       \
  X(PFNGLUSEPROGRAMPROC, UseProgram)                             \
  X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation)             \
  X(PFNGLUNIFORM1IPROC, Uniform1i)                               \
  X(PFNGLUNIFORM1FPROC, Uniform1f)                               \
  X(PFNGLUNIFORM2FPROC, Uniform2f)                               \
  X(PFNGLUNIFORM3FPROC, Uniform3f)                               \
  X(PFNGLUNIFORM4FPROC, Uniform4f)                               \
  X(PFNGLUNIFORM4IPROC, Uniform4i)                               \
  X(PFNGLUNIFORM4FVPROC, Uniform4fv)                             \
  X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv)                 \
  X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays)                   \
  X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray)                   \
  X(PFNGLDELETEVERTEXARRAYSPROC, DeleteVertexArrays)             \
  X(PFNGLGENBUFFERSPROC, GenBuffers)                             \
  X(PFNGLBINDBUFFERPROC, BindBuffer)                             \
  X(PFNGLBUFFERDATAPROC, BufferData)                             \
  X(PFNGLBUFFERSUBDATAPROC, BufferSubData)                       \
  X(PFNGLDELETEBUFFERSPROC, DeleteBuffers)                       \
  X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer)           \
  X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray)   \
  X(PFNGLDISABLEVERTEXATTRIBARRAYPROC, DisableVertexAttribArray) \
  X(PFNGLVERTEXATTRIB4FPROC, VertexAttrib4f)                     \
  X(PFNGLDRAWELEMENTSPROC, DrawElements)                         \
  X(PFNGLDRAWARRAYSPROC, DrawArrays)                             \
  X(PFNGLGENTEXTURESPROC, GenTextures)                           \
  X(PFNGLBINDTEXTUREPROC, BindTexture)                           \
  X(PFNGLDELETETEXTURESPROC, DeleteTextures)                     \
  X(PFNGLTEXIMAGE2DPROC, TexImage2D)                             \
  X(PFNGLTEXSUBIMAGE2DPROC, TexSubImage2D)                       \
  X(PFNGLTEXPARAMETERIPROC, TexParameteri)                       \
  X(PFNGLACTIVETEXTUREPROC, ActiveTexture)                       \
  X(PFNGLGENFRAMEBUFFERSPROC, GenFramebuffers)                   \
  X(PFNGLBINDFRAMEBUFFERPROC, BindFramebuffer)                   \
  X(PFNGLDELETEFRAMEBUFFERSPROC, DeleteFramebuffers)             \
  X(PFNGLFRAMEBUFFERTEXTURE2DPROC, FramebufferTexture2D)         \
  X(PFNGLCHECKFRAMEBUFFERSTATUSPROC, CheckFramebufferStatus)     \
  X(PFNGLBLITFRAMEBUFFERPROC, BlitFramebuffer)

namespace probeless::render::internal {

struct Gl {
#define PROBELESS_GL_MEMBER(type, name) type name = nullptr;
  PROBELESS_GL_FUNCTIONS(PROBELESS_GL_MEMBER)
#undef PROBELESS_GL_MEMBER
};

}  // namespace probeless::render::internal
